"""The alpha-beta tracker's cores ([Chen]): one pipelined loop shared by many tracks.

The update is the model's own (``model/alphabeta.py``), through the steps of the constant-velocity
loop (``hw/cvloop.py``), which [Zhong]'s steady-state filter runs too: xp = x + T v, e = z - xp,
x = xp + alpha e, T v = T v + beta e; the two differ only in their gains and names.

* :class:`SteadyCore`: the loop over L register stages with ``channels`` independent
  states, each one axis of one track (:class:`~kfpga.hw.core.LoopPipeline`). Up to 8 states
  live in registers; more (up to 512: 256 tracks of two axes) live in M4K block memory.
* :class:`TrackerCore`: the many-track interface around it. Its input stream carries
  ``(track, axis, z)``, its output stream ``(track, axis, x, v, overflow)``; track ``t`` axis
  ``a`` is state ``2 t + a``.
"""

from __future__ import annotations

from amaranth import Cat, Module, signed, unsigned
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from kfpga.core.codes import CODE_FORMAT
from kfpga.hw.cvloop import CUTS, ConstantGainLoop, steady_correct, steady_predict, steady_products
from kfpga.hw.storage import check_channels, m4k_blocks
from kfpga.model import cvloop as eq
from kfpga.model import start
from kfpga.model.alphabeta import MAX_TRACKS
from kfpga.model.start import START

__all__ = ["SteadyCore", "TrackerCore", "make_core", "tracker_m4k_blocks"]


def _innovation(ops, k, v):
    v["e"] = eq.innovation(ops, v["z"], v["xl1"])                       # e = z - xp
    return v


class SteadyCore(ConstantGainLoop):
    """The alpha-beta loop, ``channels`` states (1..512) interleaved; see :class:`~kfpga.hw.cvloop.ConstantGainLoop`
    for the pipeline and the stream contract, and :class:`~kfpga.hw.core.LoopPipeline` for the
    block-memory states past 8 (a state repeated back to back stalls; nothing is forwarded)."""

    steps = (steady_predict, _innovation, steady_products, steady_correct)
    reads = ({"x1", "v"}, {"z", "xl1"}, {"e"}, {"xl1", "v", "k1e", "k2e"})
    cuts = CUTS
    max_channels = 2 * MAX_TRACKS

    rate_output = "v"

    def outputs(self, live):
        return {"x": live["x1_next"], "v": live["v_next"]}

    @property
    def m4k_blocks(self):
        """M4K blocks of the state memory (0 when the states are registers)."""
        return tracker_m4k_blocks(self.config, self.channels)


def tracker_m4k_blocks(config, states):
    """M4K blocks holding ``states`` words of x1, v and the start's count (0 for 8 states or
    fewer: registers)."""
    if states <= 8:
        return 0
    f = config.formats
    return m4k_blocks(states, f["x1"].width + f["v"].width + (START.width if start.measured(config.params) else 0))


def _track_bits(tracks):
    return max(1, (tracks - 1).bit_length())


class TrackerCore(wiring.Component):
    """``tracks`` independent 2-D tracks through one :class:`SteadyCore` (``2 * tracks`` states).

    One measurement per clock across tracks, in any order of track ids; the same track and axis
    again before its previous update has written back waits (L cycles in registers, L + 1 in
    block memory). A track id outside ``0..tracks-1`` gives the estimate of a zero state and
    changes nothing.

    Members
    -------
    i : In(stream.Signature({track, axis, z}))
    o : Out(stream.Signature({track, axis, x, v, overflow}))
    overflow : Out(1)
        Sticky: some write saturated since reset.
    """

    def __init__(self, config, *, tracks=1, stages=4):
        check_channels(tracks, MAX_TRACKS, "tracks")
        self.config = config
        self.tracks = tracks
        # the state number 2 track + axis, as wide as the track field allows (an id past the last
        # track must not alias a valid state)
        self.core = SteadyCore(config, channels=2 * tracks, stages=stages, index_bits=_track_bits(tracks) + 1)
        f = config.formats
        bits = _track_bits(tracks)
        super().__init__({
            "i": In(stream.Signature(data.StructLayout({"track": unsigned(bits), "axis": 1, "z": signed(CODE_FORMAT.width)}))),
            "o": Out(stream.Signature(data.StructLayout({"track": unsigned(bits), "axis": 1,
                                                         **{o.name: signed(f[o.point].width) for o in config.outputs},
                                                         "overflow": 1}))),
            "overflow": Out(1),
        })

    @property
    def latency(self):
        return self.core.latency

    @property
    def m4k_blocks(self):
        return self.core.m4k_blocks

    @property
    def core_word_bits(self):
        """Bits of one state word (x1 and v)."""
        f = self.config.formats
        return f["x1"].width + f["v"].width

    def elaborate(self, platform):
        m = Module()
        m.submodules.core = core = self.core
        bits = _track_bits(self.tracks)
        m.d.comb += [
            core.i.valid.eq(self.i.valid), self.i.ready.eq(core.i.ready),
            core.i.payload.channel.eq(Cat(self.i.payload.axis, self.i.payload.track)),
            core.i.payload.z.eq(self.i.payload.z),
            self.o.valid.eq(core.o.valid), core.o.ready.eq(self.o.ready),
            self.o.payload.axis.eq(core.o.payload.channel[0]),
            self.o.payload.track.eq(core.o.payload.channel[1:1 + bits]),
            self.o.payload.overflow.eq(core.o.payload.overflow),
            self.overflow.eq(core.overflow),
        ]
        m.d.comb += [getattr(self.o.payload, o.name).eq(getattr(core.o.payload, o.name)) for o in self.config.outputs]
        return m


def make_core(config, variant, *, channels=1, stages=None, tracks=None):
    """The alpha-beta loop with ``channels`` states (the registry's core; ``stages`` default 4), or
    with ``tracks`` the many-track core (:class:`TrackerCore`, two states a track)."""
    if variant != "steady":
        raise ValueError(f"variant must be 'steady' (the alpha-beta tracker has constant gains), not {variant!r}")
    stages = 4 if stages is None else stages
    if tracks is not None:
        if channels != 1:
            raise ValueError(f"a tracker's states are two a track: channels does not apply with tracks ({channels})")
        return TrackerCore(config, tracks=tracks, stages=stages)
    return SteadyCore(config, channels=channels, stages=stages)
