# amaranth: UnusedElaboratable=no
"""The contract every registered filter passes: one suite, parametrised over the registry.

A new filter gets all of it by registering (``kfpga/core/registry.py``):

1. the bit-accurate model equals an exact-rational evaluation of the same equations
   (:class:`~kfpga.core.ops.FractionOps`), on random configs; the direct integer backend and the
   batch path give the same integers;
2. the RTL in the Amaranth simulator equals the model, with random valid/ready on both sides;
3. one output per input, never more;
4. the declared ``latency`` and ``cycles_per_update`` are the measured ones;
5. the generated Verilog parses as Verilog-2001 and lints;
6. cocotb on the generated Verilog is bit-exact, briefly, on Verilator and on Icarus, and the
   state holds while the core waits (the first sample 0..3 idle cycles after a reset);
7. the whole design (clock divider, ADS8364 controller, core) is bit-exact on both simulators.

A core that takes many cycles per update (the folded core of a slow filter) runs fewer
samples in the simulations: as many as :data:`CYCLE_BUDGET` cycles take, at least
:data:`MIN_SAMPLES`; in Amaranth's simulator (about 4,000 cycles a second), as many as
:data:`PYSIM_CYCLES` take, at least two a channel (``KFPGA_PYSIM_CYCLES`` sets the budget).
"""

import contextlib
import dataclasses
import os

import numpy as np
import pytest

from kfpga.core import registry
from kfpga.core.codes import CODE_MAX, CODE_MIN
from kfpga.core.config import ConfigError, FilterConfig
from kfpga.core.fixed import QFormat, Rounding
from kfpga.core.fixedmodel import FixedModel
from kfpga.core.formats import MULTIPLIER_BITS
from kfpga.core.spec import resolve
from kfpga.hw.cores import make_core
from kfpga.hw.generate import write_block
from kfpga.hw.tools import iverilog_parse, iverilog_path, verilator_lint
from kfpga.sim.amaranth_streams import measure_timing, run_core
from kfpga.sim.runner import SIMULATORS, build, run
from tests.helpers.pipeline import stage_table_faults
from tests.helpers.simulators import need

ROUNDINGS = [r.value for r in Rounding]
#: Clock cycles a simulation's samples may take at the core's rate, and the fewest samples.
CYCLE_BUDGET, MIN_SAMPLES = 150_000, 30
#: The same in Amaranth's simulator, which runs a folded core's long updates some hundred times
#: slower than Verilator: the long runs are the simulators' (test_cosimulation_is_bit_exact).
PYSIM_CYCLES = int(os.environ.get("KFPGA_PYSIM_CYCLES", "25000"))

CASES = [pytest.param(spec.name, variant, id=f"{spec.name}-{variant}")
         for spec in registry.specs() for variant in spec.model.variants]
#: Every variant on every architecture that runs it with its default parameters (the folded
#: core runs every variant).
HW_CASES = [pytest.param(spec.name, variant, architecture, id=f"{spec.name}-{variant}-{architecture}")
            for spec in registry.specs() for variant in spec.model.variants
            for architecture in spec.architectures(variant, spec.params())]


def long_tier(cases, pick):
    """``cases`` with those ``pick(*values)`` chooses marked for the long tier (``make test-long``)."""
    return [pytest.param(*c.values, id=c.id, marks=pytest.mark.long) if pick(*c.values) else c for c in cases]


#: The roll predictor's square-root update on the folded core takes some 12,000 cycles: its
#: Amaranth-simulator runs of many updates are in the long tier.
def slow_update(name, variant, architecture="folded", *_):
    return (name, variant, architecture) == ("roll", "sqrt", "folded")


def random_config(spec, variant, rng):
    """Random parameters, and formats near (and sometimes well below) their defaults; valid. Half of
    the configs have a narrow word budget, so that most cast points get formats of their own."""
    for _ in range(200):
        params = spec.random_params(rng)
        if "init" in {f.name for f in dataclasses.fields(params)} and rng.random() < 0.4:
            with contextlib.suppress(ValueError):  # the start from the first samples, where the model has one
                params = dataclasses.replace(params, init="measurement")
        budget = {"max_word": int(rng.integers(10, 37))} if rng.random() < 0.5 else {}
        try:
            base = FilterConfig(filter=spec.name, params=params, **budget)
            base.require_variant(variant)
        except ConfigError:
            continue
        formats = {}
        for name, fmt in base.formats.items():
            point = spec.model.points[name]
            if point.same_as is not None:
                continue
            i = max(1, fmt.int_bits + int(rng.integers(-3, 2)))
            f = max(0, fmt.frac_bits + int(rng.integers(-3, 3)))
            if point.operand:
                i = min(i, MULTIPLIER_BITS)
                f = min(f, MULTIPLIER_BITS - i)
            formats[name] = QFormat(i, f, str(rng.choice(ROUNDINGS)),
                                    str(rng.choice(["saturate", "saturate", "wrap"])))
        for name in base.formats:
            same = spec.model.points[name].same_as
            if same is not None:
                formats[name] = formats[same].with_rules(rounding=str(rng.choice(ROUNDINGS)))
        try:
            return FilterConfig(filter=spec.name, params=params, formats=formats, check_ranges=False, **budget)
        except ConfigError:
            continue
    raise AssertionError(f"no valid random config for {spec.name} in 200 tries")


def samples_for(config, variant, n, channels=1, architecture=None, *, pysim=False):
    """``n``, or fewer for a core whose updates take many cycles (see the module docstring);
    ``pysim``: for a run in Amaranth's simulator."""
    from kfpga.hw.generate import figures_only

    cycles = figures_only(make_core(config, variant, channels=channels,
                                                architecture=architecture)).cycles_per_update
    budget, least = (PYSIM_CYCLES, 2 * channels) if pysim else (CYCLE_BUDGET, MIN_SAMPLES)
    return max(least, min(n, budget // cycles))


def codes(rng, n):
    """Noise, a random walk, full-scale steps and the extreme codes."""
    walk = np.cumsum(rng.normal(0, 200, n))
    y = walk + rng.normal(0, 30, n)
    y[n // 3: n // 3 + 20] = CODE_MAX
    y[n // 2: n // 2 + 20] = CODE_MIN
    y[rng.integers(0, n, 10)] = CODE_MIN
    return np.clip(np.round(y), CODE_MIN, CODE_MAX).astype(np.int64)


def stimulus(config, rng, n):
    if len(config.inputs) == 1:
        return codes(rng, n)
    return {name: codes(rng, n) for name in config.inputs}


@pytest.mark.parametrize(("name", "variant"), CASES)
def test_model_equals_the_exact_rational_spec(name, variant, seed):
    rng = np.random.default_rng(seed)
    spec = registry.get(name)
    for trial in range(8):
        config = random_config(spec, variant, rng)
        y = stimulus(config, rng, 300)
        model = FixedModel(config, variant=variant)
        res = model.run(y)
        spec_run = model.run_exact(y)
        exact, flags = spec_run.outputs, spec_run.overflow
        where = f"trial {trial}: {config.params} {({k: str(f) for k, f in config.formats.items()})}"
        for field in config.output_names:
            np.testing.assert_array_equal(res.outputs[field], exact[field], err_msg=f"{field}, {where}")
        np.testing.assert_array_equal(res.overflow, flags, err_msg=f"overflow, {where}")
        # the direct integer backend, and the batch path, give the same integers
        direct = model.run_ops(y)
        batch = model.run(np.stack([y, y[::-1]]) if not isinstance(y, dict)
                          else {k: np.stack([a, a[::-1]]) for k, a in y.items()})
        for field in config.output_names:
            np.testing.assert_array_equal(direct.outputs[field], exact[field], err_msg=f"run_ops {field}, {where}")
            np.testing.assert_array_equal(batch.outputs[field][0], exact[field], err_msg=f"batch {field}, {where}")
        np.testing.assert_array_equal(batch.overflow[0], flags)


@pytest.mark.parametrize(("name", "variant", "architecture"), HW_CASES)
@pytest.mark.parametrize("channels", [1, 3])
def test_rtl_equals_model_with_backpressure(name, variant, architecture, channels, seed):
    """Random valid/ready on both sides, several channel states; every field, one output per input."""
    config = FilterConfig(filter=name)
    rng = np.random.default_rng(seed)
    n = samples_for(config, variant, 1500, channels, architecture, pysim=True)
    report = run_core(config, variant, codes(rng, n), seed=seed, channels=channels, p_idle=0.3, p_ready=0.5,
                      options={"architecture": architecture})
    assert report["compared"] == n and report["extra"] == 0


@pytest.mark.parametrize("name", registry.names())
def test_a_core_refuses_a_variant_its_filter_does_not_have(name):
    """Every core, whatever builds it, refuses with the config's own message: never a KeyError
    from deep inside, never a core half built."""
    from kfpga.hw.folded import FoldedCore

    spec = registry.get(name)
    config = FilterConfig(filter=name)
    with pytest.raises(ConfigError) as refused:
        config.require_variant("no-such-variant")
    makers = [lambda: FoldedCore(config, "no-such-variant")]
    if spec.parallel:
        own = resolve(registry.core_target(name))
        makers.append(lambda: own(config, "no-such-variant"))
    for make in makers:
        with pytest.raises(ValueError, match=r"variant must be") as got:
            make()
        assert isinstance(got.value, ConfigError) or "no-such-variant" in str(got.value)
    with pytest.raises(ConfigError) as got:
        FoldedCore(config, "no-such-variant")
    assert str(got.value) == str(refused.value)


@pytest.mark.parametrize(("name", "variant", "architecture"), long_tier(HW_CASES, slow_update))
def test_declared_latency_and_cycles_per_update_are_measured(name, variant, architecture):
    config = FilterConfig(filter=name)
    dut = make_core(config, variant, architecture=architecture)
    latency, accepted, produced = measure_timing(dut, config)
    assert latency == dut.latency
    # once an input register has filled, inputs are taken and estimates given once per update
    assert accepted[2:7] == [dut.cycles_per_update] * 5
    assert produced[:5] == [dut.cycles_per_update] * 5


def test_every_loop_pipeline_cuts_between_its_steps():
    """Every parallel core that is a loop pipeline, as each filter's default config builds it: its
    stage table puts each register stage around at least one step (:func:`stage_table_faults`)."""
    from kfpga.hw.core import LoopPipeline

    checked = {}
    for spec in registry.specs():
        config = FilterConfig(filter=spec.name)
        for variant in spec.model.variants:
            if "parallel" in spec.architectures(variant, spec.params()):
                core = make_core(config, variant, architecture="parallel")
                if isinstance(core, LoopPipeline):
                    checked[f"{spec.name}-{variant}"] = stage_table_faults(core)
    assert len(checked) >= 3, checked  # kalman2, kalman and alphabeta have steady loops
    assert {case: faults for case, faults in checked.items() if faults} == {}


@pytest.mark.parametrize(("name", "variant", "architecture"), HW_CASES)
def test_generated_verilog_parses_and_lints(name, variant, architecture, tmp_path):
    config = FilterConfig(filter=name)
    path, _ = write_block(tmp_path, "core", config, variant=variant, channels=3, architecture=architecture)
    rc, out = verilator_lint(path, path.stem, path.parent / "verilator_lint.vlt")
    assert rc == 0, out
    if iverilog_path():
        rc, out = iverilog_parse(path, path.stem)
        assert rc == 0, out
    elif os.environ.get("CI") == "true":
        pytest.fail("CI must check the Verilog-2001 parse with iverilog")


@pytest.mark.cosim
@pytest.mark.parametrize("simulator", SIMULATORS)
@pytest.mark.parametrize(("name", "variant", "architecture"), HW_CASES)
def test_cosimulation_is_bit_exact(name, variant, architecture, simulator, seed):
    need(simulator)
    config = FilterConfig(filter=name)
    n = samples_for(config, variant, 1500, 3, architecture)
    result = run(build(simulator, "core", config=config, variant=variant, channels=3, architecture=architecture),
                 "test_core", testcase="core_bit_exact",
                 params={"variant": variant, "seed": seed, "samples": n, "channels": 3, "p_idle": 0.2,
                         "p_ready": 0.7, "config_toml": config.to_toml(), "architecture": architecture},
                 tag=f"contract-{name}-{variant}-{architecture}")
    assert result["mismatches"] == 0 and result["ok"], result.get("first_mismatches")
    assert result["samples"] == n


@pytest.mark.cosim
@pytest.mark.parametrize("simulator", SIMULATORS)
@pytest.mark.parametrize(("name", "variant", "architecture"), HW_CASES)
def test_state_holds_while_the_core_waits(name, variant, architecture, simulator, seed):
    """The first sample 0, 1, 2 or 3 idle cycles after a reset, then samples at full rate: every
    estimate the model's (a state register that drifts while the core idles fails one of them)."""
    need(simulator)
    config = FilterConfig(filter=name)
    per_gap = max(8, min(40, samples_for(config, variant, 160, 3, architecture) // 4))  # 4 gaps, 0..3 cycles
    result = run(build(simulator, "core", config=config, variant=variant, channels=3, architecture=architecture),
                 "test_core", testcase="core_idle_after_reset",
                 params={"variant": variant, "seed": seed, "samples": 4 * per_gap, "channels": 3,
                         "config_toml": config.to_toml(), "architecture": architecture},
                 tag=f"contract-idle-{name}-{variant}-{architecture}")
    assert result["ok"] and result["compared"] == 4 * per_gap


@pytest.mark.cosim
@pytest.mark.parametrize("simulator", SIMULATORS)
@pytest.mark.parametrize(("name", "variant", "architecture"), HW_CASES)
def test_whole_design_is_bit_exact(name, variant, architecture, simulator, seed):
    """The core on the board: clock divider, ADS8364 controller and core, with the Verilog ADC
    model checking every timing figure; a core slower than the ADC paces its reads."""
    from kfpga.sim import system

    need(simulator)
    config = FilterConfig(filter=name)
    n = samples_for(config, variant, 400, 1, architecture)
    result = system.run(system.build(simulator, config=config, variant=variant, architecture=architecture),
                        params={"seed": seed}, samples=n, tag=f"contract-{name}-{variant}-{architecture}")
    assert result["mismatches"] == 0 and result["ok"], result.get("first_mismatches")
    assert result["samples"] == n and result["outputs"] == n and result["adc_errors"] == 0


def flag_alone_configs(config, variant, y, most=3):
    """Configs with one point narrowed (the fewest integer bits taken off) so that it saturates on
    some samples of ``y`` where no other point does: ``[(point, config, mask of those samples)]``,
    the points with the most such samples first, at most ``most``."""
    found = []
    n_samples = len(next(iter(y.values())) if isinstance(y, dict) else y)
    for point in FixedModel(config, variant=variant).run(y).overflow_points:
        fmt = config.formats.get(point)
        if fmt is None or config.spec.model.points[point].same_as is not None:
            continue
        for int_bits in range(fmt.int_bits - 1, 0, -1):
            formats = {**config.formats, point: QFormat(int_bits, fmt.frac_bits, fmt.rounding)}
            for name, p in config.spec.model.points.items():  # a point sharing its format narrows with it
                if p.same_as == point and name in formats:
                    formats[name] = formats[point].with_rules(rounding=config.formats[name].rounding)
            try:
                narrow = FilterConfig(filter=config.filter, params=config.params, formats=formats, check_ranges=False)
            except ConfigError:
                break
            flags = FixedModel(narrow, variant=variant).run(y).overflow_points
            shared = {point} | {n for n, p in config.spec.model.points.items() if p.same_as == point}
            others = np.logical_or.reduce([f for n, f in flags.items() if n not in shared] or [np.zeros(n_samples, bool)])
            alone = np.logical_or.reduce([flags[n] for n in shared if n in flags]) & ~others
            if alone.any():
                found.append((point, narrow, alone))
                break
    return sorted(found, key=lambda f: -int(f[2].sum()))[:most]


@pytest.mark.parametrize(("name", "variant", "architecture"), HW_CASES)
def test_each_overflow_flag_reaches_the_estimate_on_its_own(name, variant, architecture, seed):
    """A point made narrow, so that it saturates on samples where no other point does: there the
    estimate's flag is that point's alone, and a core that dropped it would differ from the model
    (up to three points of each core; a filter none of whose writes can overflow at its default
    formats has none to narrow, and that is checked instead)."""
    from kfpga.sim.sources import stress_codes

    config = FilterConfig(filter=name)
    n = samples_for(config, variant, 1200, 1, architecture, pysim=True)
    # fixed codes: the samples that saturate are found in them, seed or not
    y = stress_codes(1, n) if len(config.inputs) == 1 else {k: stress_codes(1 + 7 * j, n)
                                                             for j, k in enumerate(config.inputs)}
    cases = flag_alone_configs(config, variant, y)
    if not cases:
        assert not FixedModel(config, variant=variant).kernel(False).sites, "a write that can overflow, never alone"
        return
    for point, narrow, alone in cases:
        report = run_core(narrow, variant, y, seed=seed, p_idle=0.2, p_ready=0.6,
                          options={"architecture": architecture})  # every flag against the model
        assert report["got"]["overflow"][alone].all(), point


#: The designs of the filters whose models have cast points (a product's own result format).
CAST_CASES = [case for case in HW_CASES
              if any(registry.get(case.values[0]).model.points[p].cast for p in FilterConfig(filter=case.values[0]).casts)]


def cast_config(name, rng):
    """The filter's default model with a narrow word budget (every cast point gets a format), each
    cast rounded by a random rule."""
    config = FilterConfig(filter=name, max_word=14)
    casts = {p: fmt.with_rules(rounding=str(rng.choice(ROUNDINGS))) for p, fmt in config.casts.items() if fmt}
    return FilterConfig(filter=name, formats={**config.formats, **casts}, max_word=14)


@pytest.mark.parametrize(("name", "variant", "architecture"), CAST_CASES)
def test_rtl_rounds_every_cast_point_as_the_model(name, variant, architecture, seed):
    """Every cast point with a format of its own and a random rounding rule: the RTL equals the
    model, with backpressure."""
    rng = np.random.default_rng(seed)
    config = cast_config(name, rng)
    assert config.casts and all(config.casts.values())
    n = samples_for(config, variant, 600, 1, architecture, pysim=True)
    report = run_core(config, variant, codes(rng, n), seed=seed, p_idle=0.3, p_ready=0.6,
                      options={"architecture": architecture})
    assert report["compared"] == n


@pytest.mark.parametrize(("name", "variant", "architecture"),
                         long_tier(CAST_CASES, lambda name, variant, architecture: architecture == "folded"))
def test_a_wrong_rounding_of_one_product_is_caught(name, variant, architecture, seed):
    """A core built with one cast point rounded by another rule than the model's: the scoreboard
    finds it (the contract can fail on a per-operation format)."""
    rng = np.random.default_rng(seed)
    config = cast_config(name, rng)
    n = samples_for(config, variant, 400, 1, architecture)
    y = codes(rng, n)
    model = FixedModel(config, variant=variant).run(y)
    for point, fmt in config.casts.items():
        other = next(r for r in ROUNDINGS if r != fmt.rounding.value)
        planted = FilterConfig(filter=name, formats={**config.formats, point: fmt.with_rules(rounding=other)},
                               max_word=14)
        changed = FixedModel(planted, variant=variant).run(y)
        if any((changed.outputs[f] != model.outputs[f]).any() for f in config.output_names):
            break  # a rounding of this point that the outputs show
    else:
        raise AssertionError(f"no cast point of {name} changes an output when its rounding changes")
    caught = run_core(planted, variant, y, seed=seed, options={"architecture": architecture}, model_config=config,
                      check=False)
    assert caught["mismatches"] > 0, point
    # and built with the planted rule, the core is the planted model's
    assert run_core(planted, variant, y, seed=seed, options={"architecture": architecture})["compared"] == n
