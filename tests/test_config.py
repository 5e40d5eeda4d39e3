"""Config: defaults from range analysis, validation messages, TOML round trip."""

import re

import numpy as np
import pytest

from kfpga.core.config import ConfigError, FilterConfig, analysed_ranges
from kfpga.core.fixed import QFormat
from kfpga.core.fixedmodel import FixedModel
from kfpga.model.kalman2 import POINTS
from kfpga.model.reference import KalmanParams
from tests.helpers.expected import REGISTERED

KalmanConfig = FilterConfig  # the paper's filter is the default


def exactly(message):
    """A ``match=`` pattern for exactly this message."""
    return "^" + re.escape(message) + "$"


def test_defaults_cover_the_analysed_ranges_with_a_guard_bit():
    cfg = KalmanConfig()
    ranges = cfg.ranges()
    for name, fmt in cfg.formats.items():
        if name not in ranges:
            continue
        assert fmt.covers(ranges[name]), name
        if name != "e":  # the innovation gives up its guard bit to keep one fraction bit
            assert fmt.int_bits >= 2 and QFormat(fmt.int_bits - 1, fmt.frac_bits).covers(ranges[name]), name
            narrower = QFormat(fmt.int_bits - 2, fmt.frac_bits) if fmt.int_bits > 2 else None
            assert narrower is None or not narrower.covers(ranges[name]), f"{name} has more than one guard bit"
    for name, point in POINTS.items():
        if point.operand and name in cfg.formats:
            assert cfg.formats[name].width <= 18, name


def test_default_innovation_covers_a_full_scale_step():
    e = KalmanConfig().formats["e"]
    assert e.width == 18 and e.frac_bits >= 1 and e.covers(65535)


def test_ranges_reflect_the_full_scale_stimulus():
    ranges = analysed_ranges(KalmanParams())
    assert ranges["e"] == 65535.0  # a full-scale step from a settled state
    assert 32768 < ranges["x1"] < 2 * 32768  # overshoot beyond the input range
    assert 0.7 < ranges["gain"] < 1.0


@pytest.mark.parametrize(("model", "message"), [
    ({"R": 0.0}, "model.R must be > 0, not 0.0"),
    ({"R": -4.0}, "model.R must be > 0, not -4.0"),
    ({"Q": -1.0}, "model.Q must be >= 0, not -1.0"),
    ({"T": 0.0}, "model.T must be > 0, not 0.0"),
    ({"T": -1.0}, "model.T must be > 0, not -1.0"),
    ({"T": float("inf")}, "model.T must be finite, not inf"),
    ({"P0": [[1.0, 2.0], [2.0, 1.0]]}, "model.P0 must be positive definite, not [[1.0, 2.0], [2.0, 1.0]] (eigenvalues -1, 3)"),
    ({"P0": [[1.0, 0.5], [0.0, 1.0]]}, "model.P0 must be symmetric, not [[1.0, 0.5], [0.0, 1.0]]"),
    ({"P0": [[1.0, 0.0], [0.0, 0.0]]}, "model.P0 must be positive definite, not [[1.0, 0.0], [0.0, 0.0]] (eigenvalues 0, 1)"),
    ({"P0": [1.0, 2.0]}, "model.P0 must be a 2x2 matrix (a list of rows), not [1.0, 2.0]"),
    ({"x0": [1.0]}, "model.x0 must have 2 entries, not 1: [1.0]"),
    ({"T": "fast"}, "model.T must be a number, not 'fast'"),
    ({"R": True}, "model.R must be a number, not True"),
])
def test_bad_model_parameters_name_the_field(model, message):
    with pytest.raises(ConfigError, match=exactly(message)):
        KalmanConfig.from_dict({"model": model})


def test_params_raise_type_and_value_errors():
    with pytest.raises(TypeError, match=exactly("T must be a number, not 'fast'")):
        KalmanParams(T="fast")
    with pytest.raises(ValueError, match=exactly("R must be > 0, not 0.0")):
        KalmanParams(R=0.0)
    with pytest.raises(TypeError):
        KalmanParams(1.0)  # keyword-only


def test_format_too_narrow_names_field_and_range():
    with pytest.raises(ConfigError, match=r"formats\.x1 = Q16\.8 covers ±32768.*reaches ±57411.*at least 17 integer bits"):
        KalmanConfig(formats={"x1": QFormat(16, 8)})


def test_no_width_is_refused_and_a_batch_past_int64_runs_exact(seed):
    """Formats whose exact sums pass 62 bits (x1 + v at 50 fraction bits: 71 bits) are taken: the
    batch runs on Python ints, and gives the integers of each channel run alone and of the
    exact-rational spec."""
    config = KalmanConfig(formats={"x1": QFormat(20, 50), "xl1": QFormat(20, 50)})
    assert max(i.width for i in config.width_report("steady").past(62)) == 71
    rng = np.random.default_rng(seed)
    y = np.clip(np.round(np.cumsum(rng.normal(0, 400, (3, 400)), axis=1)), -32768, 32767).astype(np.int64)
    y[:, 200:210] = 32767
    for variant in ("steady", "full"):
        model = FixedModel(config, variant=variant)
        assert model.kernel(True).wide
        batch = model.run(y)
        for row in range(3):
            alone = model.run(y[row])
            for field in config.output_names:
                np.testing.assert_array_equal(batch.outputs[field][row], alone.outputs[field], err_msg=f"{variant} {field}")
            np.testing.assert_array_equal(batch.overflow[row], alone.overflow)
        exact = model.run_exact(y[0, :60])
        for field in config.output_names:
            np.testing.assert_array_equal(exact.outputs[field], batch.outputs[field][0, :60], err_msg=f"{variant} {field}")


def test_an_operand_past_the_word_budget_is_built_and_reported():
    config = KalmanConfig(formats={"e": QFormat(17, 20)}, check_ranges=False)
    wide = config.over_budget("steady")
    assert wide and all(i.width > config.max_word for i in wide)
    assert any(i.kind == "product" and "e" in i.points for i in wide)
    assert not KalmanConfig().over_budget("steady")
    narrow = KalmanConfig(formats={"e": QFormat(17, 4)}, max_word=18)
    assert narrow.max_word == 18 and narrow.over_budget("steady")
    with pytest.raises(ConfigError, match=exactly("formats.max_word must be an integer >= 2 (bits), not 1")):
        KalmanConfig(max_word=1)


def test_the_word_budget_is_a_setting_of_the_formats_table():
    text = KalmanConfig(max_word=30).to_toml()
    assert "[formats]\nmax_word = 30" in text
    import tomllib

    assert KalmanConfig.from_dict(tomllib.loads(text)).max_word == 30


def test_r_too_small_for_its_format():
    with pytest.raises(ConfigError, match=exactly(
            "model.R = 1e-05 rounds to 0 in formats.s = Q7.11 (LSB 0.000488281): the divisor S = pl11 + R could "
            "be 0; give s more fraction bits")):
        KalmanConfig(params=KalmanParams(R=1e-5), formats={"s": QFormat(7, 11)}, check_ranges=False)


def test_steady_variant_needs_q():
    cfg = KalmanConfig(params=KalmanParams(Q=0.0))
    cfg.require_variant("full")
    with pytest.raises(ConfigError, match=exactly(
            "model.Q = 0.0: the steady-state variant needs Q > 0 (Q = 0 gives K_inf = 0)")):
        cfg.require_variant("steady")
    with pytest.raises(ConfigError, match=exactly(
            "variant must be one of steady, full for the kalman2 filter, not 'fast'")):
        cfg.require_variant("fast")


def test_unknown_keys_are_rejected():
    with pytest.raises(ConfigError, match=exactly("config: unknown key model.P1; the kalman2 filter has: T, Q, R, P0, x0, init")):
        KalmanConfig.from_dict({"model": {"P1": 3}})
    with pytest.raises(ConfigError, match=exactly(
            "formats.x3: unknown quantisation point; this model has x1, xl1, v, x2, e, gain, p, pl, s")):
        KalmanConfig.from_dict({"formats": {"x3": "Q4.4"}})
    with pytest.raises(ConfigError, match=exactly(
            "config: unknown section(s) modle; expected [filter], [model], [formats.*] and [board]")):
        KalmanConfig.from_dict({"modle": {}})
    with pytest.raises(ConfigError, match=exactly("formats.x1: rounding must be one of nearest, round, convergent, "
                                                  "floor, fix (half_up: nearest), not 'up'")):
        KalmanConfig.from_dict({"formats": {"x1": {"format": "Q18.8", "rounding": "up"}}})
    with pytest.raises(ConfigError, match=exactly("config: filter.name: no filter named 'kalman9'; "
                                                  "registered: " + REGISTERED)):
        KalmanConfig.from_dict({"filter": {"name": "kalman9"}})
    with pytest.raises(ConfigError, match=exactly(
            "config: unknown key(s) filter.T; [filter] has only name (the parameters go in [model])")):
        KalmanConfig.from_dict({"filter": {"name": "kalman2", "T": 1.0}})
    with pytest.raises(ConfigError, match=exactly("formats.inv_t: this kalman2 model has no point inv_t "
                                                  "(1/T, when T is not a power of two)")):
        KalmanConfig.from_dict({"formats": {"inv_t": "Q3.15"}})


def test_omitted_rules_keep_the_defaults():
    cfg = KalmanConfig.from_dict({"formats": {"x1": {"format": "Q18.10"}, "v": "Q17.9"}})
    assert cfg.formats["x1"] == QFormat(18, 10, "half_up", "saturate")
    assert cfg.formats["v"] == QFormat(17, 9, "half_up", "saturate")
    with pytest.raises(ConfigError, match=exactly("formats.x1: give either format or int_bits and frac_bits, not both")):
        KalmanConfig.from_dict({"formats": {"x1": {"format": "Q18.10", "int_bits": 18}}})


def test_formats_are_read_only_and_a_config_is_frozen():
    cfg = KalmanConfig()
    with pytest.raises(TypeError):
        cfg.formats["x1"] = QFormat(20, 8)
    with pytest.raises(AttributeError):
        cfg.check_ranges = False


def test_filter_section_names_the_filter_and_old_files_still_load():
    old = KalmanConfig.from_dict({"model": {"T": 0.5}, "formats": {"x1": "Q19.8"}})
    new = KalmanConfig.from_dict({"filter": {"name": "kalman2"}, "model": {"T": 0.5}, "formats": {"x1": "Q19.8"}})
    assert old == new and old.filter == "kalman2"


def test_toml_round_trip(tmp_path):
    cfg = KalmanConfig(params=KalmanParams(T=0.5, Q=3.0, R=2.0, P0=((5.0, 1.0), (1.0, 4.0)), x0=(3.0, -1.0)),
                       formats={"x1": QFormat(19, 9, "floor")})
    path = tmp_path / "k.toml"
    path.write_text(cfg.to_toml())
    again = KalmanConfig.from_toml(path)
    assert again.params == cfg.params
    assert again.formats == cfg.formats


def test_toml_errors(tmp_path):
    from kfpga.core.errors import InputError

    with pytest.raises(InputError, match=exactly(f"{tmp_path / 'missing.toml'}: no such config file")):
        KalmanConfig.from_toml(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[model\nT = 1")
    with pytest.raises(ConfigError, match="^" + re.escape(f"{bad}: not valid TOML: ")):
        KalmanConfig.from_toml(bad)


def test_defaults_follow_the_model():
    big = KalmanConfig(params=KalmanParams(R=400.0, Q=2.0, P0=((1000.0, 0.0), (0.0, 1000.0))))
    ranges = big.ranges()
    assert big.formats["p"].covers(ranges["p"]) and ranges["p"] == pytest.approx(1000.0)
    assert big.formats["s"].covers(ranges["s"])
    np.testing.assert_array_less(0, [big.formats[n].frac_bits for n in ("pl", "gain", "e")])
