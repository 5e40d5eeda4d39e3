"""The alpha-beta tracker's source document, rerun: ``kfpga evaluate alphabeta`` (seeds/004).

Several radar targets in straight-line uniform motion, in 2-D radar pixel coordinates with white
noise, tracked by the alpha-beta filter (float and bit-accurate), the moving mean and the Kalman
filter; RMSE of position and velocity; the additions and multiplications per update (the
paper's table 1), counted by running each filter's update on :class:`~kfpga.core.ops.CostOps`.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from kfpga.core.errors import UsageError
from kfpga.core.spec import Evaluation


@dataclass(frozen=True)
class AlphaBetaScenario:
    """The paper's scenario: targets from random points on random straight lines at constant speed.

    ``sigma`` is the radar's position noise per axis (pixels); each plot is rounded to a whole
    pixel, as a radar image gives it. Every filter starts a track from its first plot (position
    = the plot, velocity 0); RMSE counts the scans from ``settle`` on.
    """

    targets: int = 5
    scans: int = 200
    sigma: float = 2.0
    speed: tuple = (0.5, 3.0)  # pixels per scan
    area: float = 500.0  # start points in [0.1, 0.9] * area on both axes
    settle: int = 20
    window: int = 5  # the moving mean's length
    kalman_q: float = 0.01  # the Kalman filter's process noise on the rate (a little manoeuvre)

    def __post_init__(self):
        if not isinstance(self.targets, int) or isinstance(self.targets, bool) or not 1 <= self.targets <= 256:
            raise ValueError(f"--targets must be an integer 1..256, not {self.targets!r}")
        if self.scans <= self.settle + self.window:
            raise ValueError(f"scans must exceed settle + window = {self.settle + self.window}, not {self.scans}")


def _tracks(scenario, rng):
    """``(truth position (targets, 2, scans), truth velocity (targets, 2), plots (targets, 2, scans))``."""
    s = scenario
    start = rng.uniform(0.1 * s.area, 0.9 * s.area, (s.targets, 2))
    heading = rng.uniform(0, 2 * np.pi, s.targets)
    speed = rng.uniform(*s.speed, s.targets)
    vel = np.stack([speed * np.cos(heading), speed * np.sin(heading)], axis=1)
    t = np.arange(s.scans)
    truth = start[:, :, None] + vel[:, :, None] * t
    plots = np.round(truth + rng.normal(0, s.sigma, truth.shape))
    return truth, vel, plots


def _moving_mean(z, window):
    """Mean of the last ``window`` plots (fewer at the start); velocity from the newest and the
    oldest plot of the window, ``(z[k] - z[k-m+1]) / (m - 1)``."""
    n = z.shape[-1]
    c = np.cumsum(np.concatenate([np.zeros((*z.shape[:-1], 1)), z], axis=-1), axis=-1)
    k = np.arange(n)
    lo = np.maximum(0, k - window + 1)
    x = (c[..., k + 1] - c[..., lo]) / (k - lo + 1)
    v = np.where(k - lo > 0, (z[..., k] - z[..., lo]) / np.maximum(k - lo, 1), 0.0)
    return x, v


def _rmse(est_x, est_v, truth, vel, settle):
    ex = est_x[..., settle:] - truth[..., settle:]
    ev = est_v[..., settle:] - vel[:, :, None]
    # radial: both axes together, over every target and scan
    return float(np.sqrt(np.mean(np.sum(ex ** 2, axis=1)))), float(np.sqrt(np.mean(np.sum(ev ** 2, axis=1))))


def alpha_beta(scenario=None, *, seed):
    """Run the evaluation; a dict of the scenario, the RMSE rows, the operation counts and the
    series the plot draws."""
    from kfpga.core.config import FilterConfig
    from kfpga.core.fixedmodel import FixedModel, ModelState
    from kfpga.core.ops import update_cost
    from kfpga.model import alphabeta as ab
    from kfpga.model.reference import KalmanParams, kalman_decomposed

    s = AlphaBetaScenario() if scenario is None else scenario
    rng = np.random.default_rng(seed)
    truth, vel, plots = _tracks(s, rng)
    z = plots.reshape(-1, s.scans)  # one row per target and axis
    z0 = z[:, 0]
    r = s.sigma ** 2 + 1.0 / 12.0  # the noise and the rounding to whole pixels
    rows, series = [], {}

    def add(name, x, v, note, fixed=None):
        pos, speed = _rmse(x.reshape(plots.shape), v.reshape(plots.shape), truth, vel, s.settle)
        row = {"filter": name, "position_rmse": pos, "velocity_rmse": speed, "note": note}
        if fixed is not None:
            row["bit_accurate_position_rmse"], row["bit_accurate_velocity_rmse"] = _rmse(
                fixed[0].reshape(plots.shape), fixed[1].reshape(plots.shape), truth, vel, s.settle)
        rows.append(row)
        series[name] = x.reshape(plots.shape)

    add("raw plots", z, np.zeros_like(z), "the radar's plots, no filter")
    gains = {"alpha-beta (paper)": (0.5, 0.5, "alpha = beta = 0.5 as the paper states"),
             "alpha-beta (Benedict-Bordner)": (0.5, ab.benedict_bordner(0.5), "alpha = 0.5, beta = alpha^2/(2 - alpha)"),
             "alpha-beta (critically damped)": (0.5, ab.critically_damped(0.5), "alpha = 0.5, beta = (1 - sqrt(1 - alpha))^2")}
    costs = {}
    for name, (a, b, note) in gains.items():
        params = ab.AlphaBetaParams(alpha=a, beta=b, T=1.0, R=r)
        out = _from_first_plot(lambda p, zz: ab.reference(p, "steady", zz), params, z, z0)
        config = FilterConfig(filter="alpha-beta", params=params)
        model = FixedModel(config)
        state = model.initial_state((z.shape[0],))
        f1 = config.formats["x1"]
        values = dict(state.values)
        values["x1"] = (z0.astype(np.int64) << f1.frac_bits)
        result = model.run(z.astype(np.int64), ModelState(MappingProxyType(values), state.sticky))
        fixed = (model.to_float(result)["x"], model.to_float(result)["v"])
        add(name, out["x"], out["v"], note, fixed)
        costs[name] = update_cost(config, "steady")
    general = FilterConfig(filter="alpha-beta", params=ab.AlphaBetaParams(alpha=0.4, beta=0.1, R=r))
    costs["alpha-beta (any other alpha, beta)"] = update_cost(general, "steady")
    mx, mv = _moving_mean(z, s.window)
    add(f"moving mean ({s.window} plots)", mx, mv, f"mean of the last {s.window} plots; velocity over the window")
    kp = KalmanParams(T=1.0, Q=s.kalman_q, R=r, P0=((r, 0.0), (0.0, 10.0)))
    kout = _from_first_plot(lambda p, zz: kalman_decomposed(zz, p), kp, z, z0)
    add("Kalman (time-varying gain)", kout["x1"], kout["x2"], f"Q = {s.kalman_q:g}, R = sigma^2 + 1/12 = {r:.3f}")
    paper_filter = FilterConfig(params=kp, check_ranges=False)
    costs["Kalman (time-varying gain)"] = update_cost(paper_filter, "full")
    costs["Kalman (steady-state gain)"] = update_cost(paper_filter, "steady")
    return {"seed": seed, "scenario": {k: getattr(s, k) for k in s.__dataclass_fields__}, "rows": rows,
            "costs": costs, "truth": truth, "plots": plots, "series": series}


def _from_first_plot(run, params, z, z0):
    """Run a float filter from the state (first plot, 0): its x0 set per row."""
    from dataclasses import replace

    outs = [run(replace(params, x0=(float(z0[i]), 0.0)), z[i]) for i in range(z.shape[0])]
    return {k: np.stack([o[k] for o in outs]) for k in outs[0]}


def alpha_beta_table(result):
    """The report: RMSE table, operation counts, and what they say against the paper."""
    s = result["scenario"]
    lines = [f"seed {result['seed']}: {s['targets']} targets, {s['scans']} scans, noise {s['sigma']:g} px per axis, "
             f"plots rounded to whole pixels; RMSE from scan {s['settle']} on, both axes together", "",
             f"{'filter':<34} {'position RMSE':>14} {'velocity RMSE':>14} {'bit-accurate':>22}",
             f"{'':<34} {'(px)':>14} {'(px/scan)':>14} {'(px, px/scan)':>22}"]
    for r in result["rows"]:
        fixed = (f"{r['bit_accurate_position_rmse']:.4f}, {r['bit_accurate_velocity_rmse']:.4f}"
                 if "bit_accurate_position_rmse" in r else "")
        lines.append(f"{r['filter']:<34} {r['position_rmse']:>14.4f} {r['velocity_rmse']:>14.4f} {fixed:>22}")
    lines += ["", "operations per update of one axis (counted on the update itself; a 2-D track takes two):",
              f"{'filter':<40} {'additions':>9} {'multiplications':>15} {'shifts':>6} {'divisions':>9}"]
    for name, c in result["costs"].items():
        lines.append(f"{name:<40} {c['additions']:>9} {c['multiplications']:>15} {c['shifts']:>6} {c['divisions']:>9}")
    lines += ["", "against the paper:"] + [f"  {line}" for line in alpha_beta_findings(result)]
    return "\n".join(lines)


def alpha_beta_findings(result):
    """The paper's conclusions, checked on these figures."""
    rows = {r["filter"]: r for r in result["rows"]}
    mean = next(r for n, r in rows.items() if n.startswith("moving mean"))
    paper, bb = rows["alpha-beta (paper)"], rows["alpha-beta (Benedict-Bordner)"]
    kal = rows["Kalman (time-varying gain)"]
    c = result["costs"]
    ab_cost, k_cost = c["alpha-beta (any other alpha, beta)"], c["Kalman (time-varying gain)"]
    smoother = paper["position_rmse"] < mean["position_rmse"]
    out = [f"alpha-beta smoother than the moving mean (its figs. 4-5): position RMSE {paper['position_rmse']:.3f} px "
           f"with the paper's gains against {mean['position_rmse']:.3f} px: "
           + ("confirmed" if smoother else "not confirmed") + f"; its velocity, {paper['velocity_rmse']:.3f} px/scan "
           f"against the window's {mean['velocity_rmse']:.3f}, is "
           + ("better too." if paper["velocity_rmse"] < mean["velocity_rmse"] else
              "worse: beta = 0.5 lets half of each innovation into the rate."),
           f"far fewer operations than the Kalman filter (its table 1): {ab_cost['additions']} additions and "
           f"{ab_cost['multiplications']} multiplications per axis against {k_cost['additions']}, "
           f"{k_cost['multiplications']} and {k_cost['divisions']} divisions: confirmed (alpha = beta = 0.5 "
           "needs no multiplier at all: both products are shifts).",
           f"the paper's beta = 0.5 is not the best choice at alpha = 0.5: Benedict-Bordner's beta = 0.167 gives "
           f"{bb['position_rmse']:.3f} px and {bb['velocity_rmse']:.3f} px/scan; the Kalman filter "
           f"{kal['position_rmse']:.3f} px and {kal['velocity_rmse']:.3f} px/scan (it is the optimum for this "
           "noise; the paper claims no accuracy over it, only speed).",
           "the paper's table 1 gives no figures in the text we have; the counts above are this code's own."]
    return out


def alpha_beta_plot(result, path):
    """The paper's figures: the tracks (truth, plots, filtered), and the position error against time."""
    from kfpga.core.plots import pyplot, save_figure

    plt = pyplot()

    truth, plots, series = result["truth"], result["plots"], result["series"]
    fig, (a, b) = plt.subplots(1, 2, figsize=(13, 5.5))
    for t in range(truth.shape[0]):
        a.plot(plots[t, 0], plots[t, 1], ".", ms=2, color="0.6", label="plots" if t == 0 else None)
        a.plot(truth[t, 0], truth[t, 1], "-", lw=0.8, color="k", label="truth" if t == 0 else None)
        a.plot(series["alpha-beta (paper)"][t, 0], series["alpha-beta (paper)"][t, 1], "-", lw=1, color="C0",
               label="alpha-beta (paper's gains)" if t == 0 else None)
    a.set(title="targets in radar pixel coordinates", xlabel="x (px)", ylabel="y (px)")
    a.set_aspect("equal", adjustable="datalim")
    a.legend(loc="best", fontsize=8)
    for name, style in (("raw plots", ".:"), (next(n for n in series if n.startswith("moving mean")), "-"),
                        ("alpha-beta (paper)", "-"), ("alpha-beta (Benedict-Bordner)", "-"),
                        ("Kalman (time-varying gain)", "-")):
        err = np.sqrt(np.sum((series[name][0] - truth[0]) ** 2, axis=0))
        b.plot(err, style, lw=0.9, ms=2, label=name)
    b.set(title="position error of target 0", xlabel="scan", ylabel="error (px)")
    b.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)


# -- seeds/002: the 53H outlier smoother on navigation data -----------------------------------------------


def _add_arguments(parser):
    parser.add_argument("--targets", type=int, default=5, metavar="N", help="targets tracked at once, 1..256 (default: 5)")


def _check(options):
    if not 1 <= options.targets <= 256:
        raise UsageError(f"--targets must be 1..256 (the tracker's limit), not {options.targets}")


def _run(options, seed):
    return alpha_beta(AlphaBetaScenario(targets=options.targets), seed=seed)


EVALUATION = Evaluation(
    summary="seeds/004: alpha-beta tracking of radar targets against the moving mean and the Kalman filter",
    description="Targets in straight-line uniform motion in 2-D radar pixel coordinates, with white noise (2 px per "
                "axis) and plots rounded to whole pixels, tracked by the alpha-beta filter (the paper's alpha = beta "
                "= 0.5, Benedict-Bordner and critically damped beta at alpha = 0.5; float and bit-accurate), the "
                "moving mean of 5 plots and the time-varying Kalman filter. Prints the RMSE of position and velocity, "
                "the additions and multiplications per update (the paper's table 1, counted on each filter's "
                "update), and how they compare with the paper.",
    add_arguments=_add_arguments,
    check=_check,
    run=_run,
    table=alpha_beta_table,
    summary_json=lambda r: {k: r[k] for k in ("seed", "scenario", "rows", "costs")} | {"findings": alpha_beta_findings(r)},
    plot=alpha_beta_plot,
)
