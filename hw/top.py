"""Top level: clock divider + ADS8364 controller (+ a pre-filter) + a registered filter's core + output port."""

from typing import NamedTuple

from amaranth import ClockDomain, ClockSignal, Const, Module, Mux, Signal, signed
from amaranth.lib import stream, wiring
from amaranth.lib.cdc import ResetSynchronizer
from amaranth.lib.wiring import In, Out

from kfpga.core import registry
from kfpga.hw.ads8364 import CONV0, ADS8364Controller, SampleLayout
from kfpga.hw.ads8364_timing import check_rate
from kfpga.hw.clockdiv import ClockDivider
from kfpga.hw.cores import make_core

__all__ = ["FilterSystem", "AdcFrontend", "PORTS", "ADC_PINS", "out_field", "prefilters", "prefilter_core", "port_widths"]

#: Top-level ports: name -> (direction, width, description). The pin table and the .sdc use it.
PORTS = {
    "clk50": ("in", 1, "50 MHz oscillator"),
    "rst_n": ("in", 1, "reset, active low, asynchronous (synchronised inside)"),
    "adc_clk": ("out", 1, "ADS8364 CLK, 5 MHz, from a register"),
    "adc_hold_a_n": ("out", 1, "ADS8364 HOLDA"),
    "adc_hold_b_n": ("out", 1, "ADS8364 HOLDB"),
    "adc_hold_c_n": ("out", 1, "ADS8364 HOLDC"),
    "adc_eoc_n": ("in", 1, "ADS8364 EOC"),
    "adc_cs_n": ("out", 1, "ADS8364 CS"),
    "adc_rd_n": ("out", 1, "ADS8364 RD"),
    "adc_wr_n": ("out", 1, "ADS8364 WR (held high)"),
    "adc_byte": ("out", 1, "ADS8364 BYTE (held low: 16-bit reads)"),
    "adc_add": ("out", 1, "ADS8364 ADD (held low)"),
    "adc_reset_n": ("out", 1, "ADS8364 RESET"),
    "adc_addr": ("out", 3, "ADS8364 A2..A0 (adc_addr[0] = A0)"),
    "adc_data": ("in", 16, "ADS8364 D15..D0"),
    "out_data": ("out", None, "the chosen output field (default x1), two's complement in its format"),
    "out_channel": ("out", 3, "channel of out_data (0..5 = A0..C1)"),
    "out_valid": ("out", 1, "one-cycle strobe: out_data and out_channel are new"),
    "out_overflow": ("out", 1, "sticky: a saturation happened in the filter"),
    "out_timeout": ("out", 1, "sticky: an EOC timeout happened"),
}


#: The multiplexer's select, a port of a design with sensors taking turns on one ADC channel.
MUX_PORT = ("out", None, "select of the analog multiplexer in front of the ADC: the sensor converted next")


def port_widths(sensors=1):
    """``{port: (direction, width, description)}`` of the top for ``sensors`` (more than one: the
    ``mux_sel`` port, and ``out_channel`` as wide as a sensor's number); ``out_data``'s width is
    the output format's (``None`` here)."""
    from kfpga.core.board import sensor_bits

    ports = dict(PORTS)
    if sensors > 1:
        bits = sensor_bits(sensors)
        ports["out_channel"] = ("out", max(3, bits), "sensor (channel state) of out_data")
        ports["mux_sel"] = (MUX_PORT[0], bits, MUX_PORT[2])
    return ports


def _pin_members(names, out_width=None, ports=PORTS):
    members = {}
    for name in names:
        direction, bits, _ = ports[name]
        shape = signed(out_width) if name == "out_data" else bits
        init = 1 if name in ("rst_n", "adc_eoc_n") else 0
        members[name] = In(shape, init=init) if direction == "in" else Out(shape)
    return members


ADC_PINS = [name for name in PORTS if name.startswith("adc_")]


class AdcFrontend(wiring.Component):
    """Clock divider + ADS8364 controller, with the ADC pins named as on the board.

    Parameters
    ----------
    six_channel, channel, ratio, timeout_periods:
        As :class:`FilterSystem`.
    conversion_cycles:
        System cycles from one conversion's start to the next (the conversion timer); ``None``:
        the ADC converts as fast as it can. A conversion starts at the first ADC clock edge after
        the timer's tick, so each start is up to ``ratio`` cycles late, never early, and the
        rate is exactly ``clock / conversion_cycles``.

    Members
    -------
    adc_* : the ADS8364 pins of :data:`PORTS`
    o : Out(stream.Signature(SampleLayout))
        One (channel, sample) word per channel per conversion.
    timeout : Out(1)
        Sticky EOC timeout flag.
    """

    def __init__(self, *, six_channel=False, channel=0, ratio=10, timeout_periods=40, conversion_cycles=None):
        if conversion_cycles is not None and (not isinstance(conversion_cycles, int) or conversion_cycles < 1):
            raise ValueError(f"conversion_cycles must be a positive number of system cycles, not {conversion_cycles!r}")
        self.conversion_cycles = conversion_cycles
        self.divider = ClockDivider(ratio=ratio)
        self.controller = ADS8364Controller(channel=channel, six_channel=six_channel, timeout_periods=timeout_periods)
        members = _pin_members(ADC_PINS)
        members["o"] = Out(stream.Signature(SampleLayout))
        members["timeout"] = Out(1)
        super().__init__(members)

    def elaborate(self, platform):
        m = Module()
        m.submodules.divider = divider = self.divider
        m.submodules.controller = ctrl = self.controller
        word = ctrl.word
        m.d.comb += [
            ctrl.strobe.eq(divider.strobe),
            ctrl.enable.eq(self._timer(m, ctrl, divider)),
            ctrl.eoc.eq(self.adc_eoc_n),
            ctrl.data.eq(self.adc_data),
            self.adc_clk.eq(divider.clk_out),
            self.adc_hold_a_n.eq(word.hold_a),
            self.adc_hold_b_n.eq(word.hold_b),
            self.adc_hold_c_n.eq(word.hold_c),
            self.adc_cs_n.eq(word.cs),
            self.adc_rd_n.eq(word.rd),
            self.adc_wr_n.eq(word.wr),
            self.adc_byte.eq(word.byte),
            self.adc_add.eq(word.add),
            self.adc_reset_n.eq(word.reset),
            self.adc_addr.eq(ctrl.addr),
            self.timeout.eq(ctrl.timeout),
        ]
        wiring.connect(m, wiring.flipped(self.o), ctrl.o)
        return m

    def _timer(self, m, ctrl, divider):
        """The controller's enable: always (free running), or from the conversion timer: a tick
        every ``conversion_cycles`` cycles sets ``due``; the conversion's start (the controller leaving CONV0
        on a strobe with its start bit) clears it."""
        if self.conversion_cycles is None:
            return 1
        count = Signal(range(self.conversion_cycles), init=self.conversion_cycles - 1)
        due = Signal(init=1)  # the first conversion right after reset
        tick = count == 0
        m.d.sync += count.eq(Mux(tick, self.conversion_cycles - 1, count - 1))
        started = divider.strobe & (ctrl.state == CONV0) & ctrl.word.start
        with m.If(tick):
            m.d.sync += due.eq(1)
        with m.Elif(started):
            m.d.sync += due.eq(0)
        return due


class _Words(NamedTuple):
    """A stream of (ADC channel, sample) words, as the controller or the pre-filter gives them."""

    valid: object
    channel: object
    sample: object


def prefilters():
    """The registered filters that can sit between the controller and the core (a spec with a
    ``prefilter``)."""
    return [spec.name for spec in registry.specs() if spec.hardware.prefilter is not None]


def prefilter_core(config, channels):
    """The core of a pre-filter config for ``channels`` ADC channels, checked: its formats must not
    be able to overflow (its words reach the core unflagged)."""
    from kfpga.core.fixedmodel import FixedModel

    if config.spec.hardware.prefilter is None:
        raise ValueError(f"the pre-filter must be one of {', '.join(prefilters())}, not {config.filter}")
    sites = FixedModel(config).kernel(False).sites
    if sites:
        raise ValueError(f"the pre-filter's formats can overflow (at {', '.join(sites)}); its output goes to the core "
                         "unflagged, so it needs formats that cannot (its defaults)")
    return make_core(config, config.spec.default_variant, channels=channels)


def out_field(config, name=None):
    """The output field that drives ``out_data`` (default: the filter's), checked."""
    name = config.spec.model.default_output if name is None else name
    if name not in config.output_names:
        raise ValueError(f"out_field must be one of {', '.join(config.output_names)} for the {config.filter} filter, "
                         f"not {name!r}")
    return name


def out_width(config, name=None):
    """Bits of ``out_data``: the width of the chosen field's format."""
    return config.output_format(out_field(config, name)).width


def check_sensors(sensors, config, *, six_channel=False, prefilter=None):
    """``sensors`` checked for a design with this config (``ValueError`` naming the problem)."""
    from kfpga.core.board import MAX_CHANNELS

    if not isinstance(sensors, int) or isinstance(sensors, bool) or not 1 <= sensors <= MAX_CHANNELS:
        raise ValueError(f"sensors must be an integer 1..{MAX_CHANNELS}, not {sensors!r}")
    if sensors > 1:
        if six_channel:
            raise ValueError("sensors on a multiplexer take one ADC channel: not with six channels")
        if len(config.inputs) != 1:
            raise ValueError(f"sensors on a multiplexer need a one-input filter; this model reads {len(config.inputs)} "
                             "ADC channels per update")
        if prefilter is not None:
            raise ValueError("a pre-filter keeps a state per ADC channel: not with sensors on a multiplexer")
    return sensors


class FilterSystem(wiring.Component):
    """The whole FPGA design for one ADS8364: :class:`AdcFrontend` + a filter core + output port.

    Parameters
    ----------
    config:
        Shared :class:`~kfpga.core.config.FilterConfig`: the filter and its formats.
    variant:
        Which of the filter's cores (default: its first variant).
    six_channel:
        Sample and filter all six channels (one HOLD for all), each with its own state; a
        one-input filter only.
    channel:
        The channel of single-channel mode, 0..5 (default: the model's ``adc``, else 0). A
        filter with several inputs (two observations) reads the model's ADC channels instead,
        all sampled at the same instant, and makes one update of the samples of one conversion.
    ratio:
        System clock / ADC clock (10: 50 MHz -> 5 MHz).
    timeout_periods:
        EOC timeout in ADC CLK periods.
    out_field:
        The output field on ``out_data`` (default: the filter's, ``x1`` for the paper's).
    architecture, stages:
        The core's: ``parallel`` or ``folded`` (default: the parallel core where it runs), and
        the register stages of a pipelined loop (default: the core's).
    prefilter:
        ``None``, or the :class:`~kfpga.core.config.FilterConfig` of a filter that can stand before
        another (its spec's ``prefilter``, such as an outlier smoother) between the controller and
        the core: every ADC channel read has its own state, the core gets each sample as many
        samples late as the pre-filter delays it. Its formats must be ones that cannot overflow
        (the defaults).
    sensors:
        More than one (up to 256): that many sensors take turns on ADC channel ``channel``
        through an analog multiplexer whose select is the ``mux_sel`` port. Sensor ``s`` is the
        core's channel state ``s`` (block memory past eight, on a core that holds them there): the
        select names the sensor converted next; it moves on, and ``s + 1`` after ``N - 1`` wraps
        to 0, when the core takes a sample, so the multiplexer settles from then to the next
        conversion's HOLD (a conversion timer, ``[board] sample_rate_hz``, gives it the rest of the
        period). Each sensor is sampled at the board's rate, the ADC at ``sensors`` times that.

    Members
    -------
    See :data:`PORTS`; ``out_data`` is as wide as the chosen field's format.
    """

    def __init__(self, config, *, variant=None, six_channel=False, channel=None, ratio=10, timeout_periods=40,
                 out_field=None, prefilter=None, architecture=None, stages=None, sensors=1):
        spec = config.spec
        self.sensors = check_sensors(sensors, config, six_channel=six_channel, prefilter=prefilter)
        self.six_channel = bool(six_channel)
        if self.six_channel:
            if len(config.inputs) != 1:
                raise ValueError(f"six channels of their own need a one-input filter; this model reads "
                                 f"{len(config.inputs)} ADC channels per update")
            if spec.model.adc is not None and spec.model.adc(config.params) is not None:
                raise ValueError("six channels filter every ADC channel: the model's adc does not apply")
            if channel is not None:
                raise ValueError("six channels filter every ADC channel: channel does not apply")
            self.adc = (0,)
        else:
            self.adc = spec.adc_channels(config.params, channel)
        self.config = config
        self.variant = spec.default_variant if variant is None else variant
        self.channel = self.adc[0]  # the channel reported on out_channel in single-channel mode
        self.ratio = ratio
        self.out_field = globals()["out_field"](config, out_field)
        # checked first: a refused pre-filter leaves nothing built
        self.prefilter = None if prefilter is None else prefilter_core(prefilter, 6 if six_channel or len(self.adc) > 1
                                                                       else 1)
        # the pre-filter's one input and the output it passes on, by its spec's names
        self.prefilter_ports = None if prefilter is None else (
            prefilter.spec.inputs_for(prefilter.params)[0][0], prefilter.spec.model.default_output)
        # several inputs: all six are converted at one instant and read; the update takes its own
        channels = 6 if six_channel or len(self.adc) > 1 else 1
        check_rate(config.board, channels, ratio, self.sensors)
        self.frontend = AdcFrontend(six_channel=six_channel or len(self.adc) > 1, channel=self.channel, ratio=ratio,
                                    timeout_periods=timeout_periods,
                                    conversion_cycles=config.board.conversion_cycles(self.sensors))
        options = {} if stages is None else {"stages": stages}
        self.core = make_core(config, self.variant, channels=6 if six_channel else self.sensors,
                                   architecture=architecture, **options)
        self.architecture = architecture or spec.architectures(self.variant, config.params)[0]
        self.ports = port_widths(self.sensors)
        super().__init__(_pin_members(self.ports, out_width(config, self.out_field), self.ports))

    def elaborate(self, platform):
        m = Module()
        m.domains.sync = ClockDomain("sync", local=True)
        m.d.comb += ClockSignal("sync").eq(self.clk50)
        m.submodules.reset_sync = ResetSynchronizer(~self.rst_n, domain="sync")

        m.submodules.frontend = frontend = self.frontend
        m.submodules.core = core = self.core
        for name in ADC_PINS:
            pin, inner = getattr(self, name), getattr(frontend, name)
            if PORTS[name][0] == "in":
                m.d.comb += inner.eq(pin)
            else:
                m.d.comb += pin.eq(inner)
        # the controller's (ADC channel, sample) words, through the pre-filter when there is one
        source = _Words(frontend.o.valid, frontend.o.payload.channel, frontend.o.payload.sample)
        if self.prefilter is not None:
            m.submodules.prefilter = pre = self.prefilter
            pre_in, pre_out = self.prefilter_ports
            m.d.comb += [pre.i.valid.eq(frontend.o.valid), frontend.o.ready.eq(pre.i.ready),
                         getattr(pre.i.payload, pre_in).eq(frontend.o.payload.sample)]
            if self.prefilter.channels > 1:
                m.d.comb += pre.i.payload.channel.eq(frontend.o.payload.channel)
            channel = pre.o.payload.channel if self.prefilter.channels > 1 else Const(self.channel, 3)
            source = _Words(pre.o.valid, channel, getattr(pre.o.payload, pre_out))
            ready = pre.o.ready
        else:
            ready = frontend.o.ready
        # ... feed the core's (channel state, y) input
        names = self.config.inputs
        if len(names) == 1:
            m.d.comb += [
                core.i.valid.eq(source.valid),
                ready.eq(core.i.ready),
                getattr(core.i.payload, names[0]).eq(source.sample),
            ]
        else:
            # the words of one conversion come in channel order: the inputs' samples are held
            # until the last of their channels comes, which then goes to the core with them
            order = sorted(range(len(names)), key=lambda j: self.adc[j])
            last = order[-1]
            held = {}
            for j in order[:-1]:
                held[j] = Signal(signed(16), name=f"held_{names[j]}")
                with m.If(source.valid & (source.channel == self.adc[j])):
                    m.d.sync += held[j].eq(source.sample)
            is_last = source.channel == self.adc[last]
            m.d.comb += [
                core.i.valid.eq(source.valid & is_last),
                ready.eq(~is_last | core.i.ready),
                getattr(core.i.payload, names[last]).eq(source.sample),
                *(getattr(core.i.payload, names[j]).eq(held[j]) for j in held),
            ]
        if self.six_channel:  # the ADC's channel number is the core's channel state
            m.d.comb += core.i.payload.channel.eq(source.channel)
        sensor = None
        if self.sensors > 1:  # the sensor the multiplexer selects is the core's channel state
            sensor = Signal(range(self.sensors), name="sensor")
            with m.If(core.i.valid & core.i.ready):
                m.d.sync += sensor.eq(Mux(sensor == self.sensors - 1, 0, sensor + 1))
            m.d.comb += [core.i.payload.channel.eq(sensor), self.mux_sel.eq(sensor)]
        # the output port has no backpressure: each estimate is presented for one cycle
        m.d.comb += [
            core.o.ready.eq(1),
            self.out_valid.eq(core.o.valid),
            self.out_data.eq(getattr(core.o.payload, self.out_field)),
            self.out_channel.eq(core.o.payload.channel if self.six_channel or sensor is not None else self.channel),
            self.out_overflow.eq(core.overflow if self.prefilter is None else core.overflow | self.prefilter.overflow),
            self.out_timeout.eq(frontend.timeout),
        ]
        return m
