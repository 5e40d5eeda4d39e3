"""The alpha-beta tracker's source document, rerun: ``kfpga evaluate alphabeta`` ([Chen]).

Several radar targets in straight-line uniform motion, in 2-D radar pixel coordinates with white
noise, tracked by the alpha-beta filter (float and bit-accurate), the moving mean and the Kalman
filter; RMSE of position and velocity; the additions and multiplications per update (the
paper's table 1), counted by running each filter's update on :class:`~kfpga.core.ops.CostOps`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kfpga.core.errors import UsageError
from kfpga.core.spec import Evaluation


@dataclass(frozen=True)
class AlphaBetaScenario:
    """The paper's scenario: targets from random points on random straight lines at constant speed.

    ``sigma`` is the radar's position noise per axis (pixels); each plot is rounded to a whole
    pixel, as a radar image gives it. Every recursive filter starts a track from its first two
    plots (position = the second, velocity = their difference: ``init = "measurement"``); RMSE
    counts the scans from ``settle`` on. ``alpha``, ``beta``: the tracker under test (the paper's
    0.5, 0.5). ``glitch``: the share of plots thrown ``glitch_size`` pixels off in a random
    direction in the glitch-noise run (the paper's "毛刺噪声").
    """

    targets: int = 5
    scans: int = 200
    sigma: float = 2.0
    speed: tuple = (0.5, 3.0)  # pixels per scan
    area: float = 500.0  # start points in [0.1, 0.9] * area on both axes
    settle: int = 20
    window: int = 5  # the moving mean's length
    kalman_q: float = 0.01  # the Kalman filter's process noise on the rate (a little manoeuvre)
    alpha: float = 0.5
    beta: float = 0.5
    glitch: float = 0.02
    glitch_size: float = 30.0

    def __post_init__(self):
        if not isinstance(self.targets, int) or isinstance(self.targets, bool) or not 1 <= self.targets <= 256:
            raise ValueError(f"--targets must be an integer 1..256, not {self.targets!r}")
        if self.scans <= self.settle + self.window:
            raise ValueError(f"scans must exceed settle + window = {self.settle + self.window}, not {self.scans}")
        if not 0.0 <= self.glitch <= 0.5:
            raise ValueError(f"--glitch must be a share of the plots in 0..0.5, not {self.glitch!r}")
        if not 0.0 < self.glitch_size <= 1000.0:
            raise ValueError(f"--glitch-size must be in (0, 1000] pixels, not {self.glitch_size!r}")


def _tracks(scenario, rng):
    """``(truth position (targets, 2, scans), truth velocity (targets, 2), plots (targets, 2, scans),
    plots with glitches)``."""
    s = scenario
    start = rng.uniform(0.1 * s.area, 0.9 * s.area, (s.targets, 2))
    heading = rng.uniform(0, 2 * np.pi, s.targets)
    speed = rng.uniform(*s.speed, s.targets)
    vel = np.stack([speed * np.cos(heading), speed * np.sin(heading)], axis=1)
    t = np.arange(s.scans)
    truth = start[:, :, None] + vel[:, :, None] * t
    noisy = truth + rng.normal(0, s.sigma, truth.shape)
    plots = np.round(noisy)
    # glitches: whole plots (both axes) thrown glitch_size px off, never the two that start a track
    hit = rng.random((s.targets, s.scans)) < s.glitch
    hit[:, :2] = False
    angle = rng.uniform(0, 2 * np.pi, (s.targets, s.scans))
    offset = s.glitch_size * np.stack([np.cos(angle), np.sin(angle)], axis=1) * hit[:, None, :]
    return truth, vel, plots, np.round(noisy + offset)


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


def _errors(x, v, truth, vel, settle):
    """The figures of one filter's track (arrays ``(targets, 2, scans)``), from scan ``settle`` on:
    position and velocity RMSE (both axes together), the one-step prediction ``x + v`` against
    the next scan's truth, and the RMS errors of course (deg) and speed."""
    ex = x[..., settle:] - truth[..., settle:]
    ev = v[..., settle:] - vel[:, :, None]
    ep = (x + v)[..., settle:-1] - truth[..., settle + 1:]
    est = v[..., settle:]
    course = np.degrees(np.arctan2(est[:, 1], est[:, 0]) - np.arctan2(vel[:, 1], vel[:, 0])[:, None])
    course = (course + 180.0) % 360.0 - 180.0
    speed = np.hypot(est[:, 0], est[:, 1]) - np.hypot(vel[:, 0], vel[:, 1])[:, None]

    def radial(e):
        return float(np.sqrt(np.mean(np.sum(e ** 2, axis=1))))

    return {"position_rmse": radial(ex), "velocity_rmse": radial(ev), "prediction_rmse": radial(ep),
            "course_rms_deg": float(np.sqrt(np.mean(course ** 2))), "speed_rms": float(np.sqrt(np.mean(speed ** 2)))}


def _tracker(params, z):
    """The alpha-beta tracker over the rows of ``z`` (one per target and axis), in float and in the
    core's integers, both started from each row's first two plots: ``((x, v), (x, v))``."""
    from kfpga.core.config import FilterConfig
    from kfpga.core.fixedmodel import FixedModel
    from kfpga.model import alphabeta as ab

    out = ab.reference(params, "steady", z)
    model = FixedModel(FilterConfig(filter="alphabeta", params=params))
    result = model.run(z.astype(np.int64), model.initial_state((z.shape[0],)))
    fixed = model.to_float(result)
    return (out["x"], out["v"]), (fixed["x"], fixed["v"])


def alphabeta(scenario=None, *, seed):
    """Run the evaluation; a dict of the scenario, the rows (each filter's figures), the operation
    counts and the series the plot draws."""
    from dataclasses import replace

    from kfpga.core.config import FilterConfig
    from kfpga.core.ops import update_cost
    from kfpga.model import alphabeta as ab
    from kfpga.model.reference import KalmanParams, kalman_decomposed

    s = AlphaBetaScenario() if scenario is None else scenario
    rng = np.random.default_rng(seed)
    truth, vel, plots, glitched = _tracks(s, rng)
    shape = plots.shape
    z, zg = plots.reshape(-1, s.scans), glitched.reshape(-1, s.scans)  # one row per target and axis
    r = s.sigma ** 2 + 1.0 / 12.0  # the noise and the rounding to whole pixels
    kp = KalmanParams(T=1.0, Q=s.kalman_q, R=r, P0=((r, 0.0), (0.0, 10.0)))
    rows, series = [], {}

    def add(name, x, v, note, fixed=None, glitch=None, **extra):
        row = {"filter": name, **_errors(x.reshape(shape), v.reshape(shape), truth, vel, s.settle), "note": note, **extra}
        if fixed is not None:
            f = _errors(fixed[0].reshape(shape), fixed[1].reshape(shape), truth, vel, s.settle)
            row |= {f"bit_accurate_{k}": f[k] for k in ("position_rmse", "velocity_rmse", "prediction_rmse")}
        if glitch is not None:
            row["glitch_position_rmse"] = _errors(glitch[0].reshape(shape), glitch[1].reshape(shape), truth, vel,
                                                  s.settle)["position_rmse"]
        rows.append(row)
        series[name] = x.reshape(shape)

    add("raw plots", z, np.zeros_like(z), "the radar's plots, no filter", glitch=(zg, np.zeros_like(zg)))
    steady = ab.from_kalman(kp)
    gains = {"alpha-beta (paper)" if (s.alpha, s.beta) == (0.5, 0.5) else "alpha-beta (yours)":
             (s.alpha, s.beta, f"alpha = {s.alpha:g}, beta = {s.beta:g}" + (" as the paper states"
                                                                           if (s.alpha, s.beta) == (0.5, 0.5) else "")),
             "alpha-beta (Benedict-Bordner)": (0.5, ab.benedict_bordner(0.5), "alpha = 0.5, beta = alpha^2/(2 - alpha)"),
             "alpha-beta (critically damped)": (0.5, ab.critically_damped(0.5), "alpha = 0.5, beta = (1 - sqrt(1 - alpha))^2"),
             "alpha-beta (steady Kalman gains)": (steady.alpha, steady.beta,
                                                  f"alpha = {steady.alpha:.3f}, beta = {steady.beta:.3f}: the Kalman "
                                                  "filter's steady-state gains")}
    costs = {}
    for name, (a, b, note) in gains.items():
        params = ab.AlphaBetaParams(alpha=a, beta=b, T=1.0, R=r, init="measurement")
        (x, v), fixed = _tracker(params, z)
        add(name, x, v, note, fixed, glitch=tuple(ab.reference(params, "steady", zg).values()), alpha=a, beta=b)
        # the update's own operations (the start adds a subtraction and selections on two plots)
        costs[name] = update_cost(FilterConfig(filter="alphabeta", params=replace(params, init="state")), "steady")
    general = FilterConfig(filter="alphabeta", params=ab.AlphaBetaParams(alpha=0.4, beta=0.1, R=r, init="state"))
    costs["alpha-beta (any other alpha, beta)"] = update_cost(general, "steady")
    mx, mv = _moving_mean(z, s.window)
    lag = (s.window - 1) / 2.0
    add(f"moving mean ({s.window} plots)", mx, mv, f"mean of the last {s.window} plots; velocity over the window",
        glitch=_moving_mean(zg, s.window))
    gx, gv = _moving_mean(zg, s.window)
    add("moving mean, lag removed", mx + lag * mv, mv, f"the mean moved on by its lag, {lag:g} scans of its velocity",
        glitch=(gx + lag * gv, gv))
    kout = _from_first_plot(lambda p, zz: kalman_decomposed(zz, p), kp, z)
    add("Kalman (time-varying gain)", kout["x1"], kout["x2"], f"Q = {s.kalman_q:g}, R = sigma^2 + 1/12 = {r:.3f}")
    paper_filter = FilterConfig(params=kp, check_ranges=False)
    costs["Kalman (time-varying gain)"] = update_cost(paper_filter, "full")
    costs["Kalman (steady-state gain)"] = update_cost(paper_filter, "steady")
    return {"seed": seed, "scenario": {k: getattr(s, k) for k in s.__dataclass_fields__}, "rows": rows,
            "costs": costs, "truth": truth, "plots": plots, "series": series}


def _from_first_plot(run, params, z):
    """Run a float filter from the state (first plot, 0): its x0 set per row."""
    from dataclasses import replace

    outs = [run(replace(params, x0=(float(z[i, 0]), 0.0)), z[i]) for i in range(z.shape[0])]
    return {k: np.stack([o[k] for o in outs]) for k in outs[0]}


def _tested(rows):
    """The row of the tracker under test (the paper's gains, or --alpha/--beta)."""
    return next(r for r in rows if r["filter"] in ("alpha-beta (paper)", "alpha-beta (yours)"))


def alphabeta_table(result):
    """The report of one seed: each filter's figures and the operation counts."""
    s = result["scenario"]
    lines = [f"seed {result['seed']}: {s['targets']} targets, {s['scans']} scans, noise {s['sigma']:g} px per axis, "
             f"plots rounded to whole pixels; figures from scan {s['settle']} on, both axes together; every recursive "
             "filter starts a track from its first two plots", "",
             f"{'filter':<34} {'position':>9} {'velocity':>9} {'1-step':>9} {'course':>8} {'speed':>8} "
             f"{'glitches':>9} {'bit-accurate':>22}",
             f"{'':<34} {'(px)':>9} {'(px/scan)':>9} {'pred (px)':>9} {'(deg)':>8} {'(px/sc)':>8} "
             f"{'pos (px)':>9} {'(pos, 1-step pred)':>22}"]
    for r in result["rows"]:
        fixed = (f"{r['bit_accurate_position_rmse']:.4f}, {r['bit_accurate_prediction_rmse']:.4f}"
                 if "bit_accurate_position_rmse" in r else "")
        raw = r["filter"] == "raw plots"
        glitch = f"{r['glitch_position_rmse']:>9.4f}" if "glitch_position_rmse" in r else f"{'':>9}"
        lines.append(f"{r['filter']:<34} {r['position_rmse']:>9.4f} {'' if raw else format(r['velocity_rmse'], '.4f'):>9} "
                     f"{'' if raw else format(r['prediction_rmse'], '.4f'):>9} "
                     f"{'' if raw else format(r['course_rms_deg'], '.2f'):>8} "
                     f"{'' if raw else format(r['speed_rms'], '.4f'):>8} {glitch} {fixed:>22}")
    lines += ["", f"RMS errors; 1-step pred: x + v against the next scan's truth; glitches: {100 * s['glitch']:g} % of "
              f"the plots {s['glitch_size']:g} px off, position RMSE", "",
              "operations per update of one axis (counted on the update itself; a 2-D track takes two):",
              f"{'filter':<40} {'additions':>9} {'multiplications':>15} {'shifts':>6} {'divisions':>9}"]
    for name, c in result["costs"].items():
        lines.append(f"{name:<40} {c['additions']:>9} {c['multiplications']:>15} {c['shifts']:>6} {c['divisions']:>9}")
    return "\n".join(lines)


def alphabeta_claims(options, result, runs):
    """The paper's claims, judged on every seed's rows."""
    from kfpga.core.claims import Claim, spread

    def rows(run):
        return {r["filter"]: r for r in run["rows"]}

    def fig(name, key):
        return [rows(run)[name][key] if name in rows(run) else _tested(run["rows"])[key] for run in runs]

    tested = _tested(result["rows"])["filter"]
    mean, lagless = next(n for n in rows(result) if n.startswith("moving mean (")), "moving mean, lag removed"
    others = ("alpha-beta (Benedict-Bordner)", "alpha-beta (critically damped)", "alpha-beta (steady Kalman gains)")
    ab, mm, ml = fig(tested, "position_rmse"), fig(mean, "position_rmse"), fig(lagless, "position_rmse")
    pred, raw = fig(tested, "prediction_rmse"), fig("raw plots", "position_rmse")
    gab, gmm = fig(tested, "glitch_position_rmse"), fig(mean, "glitch_position_rmse")
    best_other = [min(rows(run)[o]["position_rmse"] for o in others) for run in runs]
    c = result["costs"]
    ab_cost, k_cost = c["alpha-beta (any other alpha, beta)"], c["Kalman (time-varying gain)"]
    from kfpga.model import alphabeta as abm

    bb, cd = abm.benedict_bordner(0.5), abm.critically_damped(0.5)
    return [
        Claim(f"the alpha-beta track is smoother and closer to the target than the mean filter's (figs. 4-5; "
              f"{tested}, moving mean of {result['scenario']['window']})",
              "fig. 5 better than fig. 4 (curves, no figure)", [a < m for a, m in zip(ab, mm, strict=True)],
              f"position RMSE {spread(ab)} px against {spread(mm)} px"),
        Claim("... and than the mean filter once its lag is removed (the same window, moved on by (m-1)/2 scans of "
              "its velocity)", "not in the paper: the fair form of the same comparison",
              [a < m for a, m in zip(ab, ml, strict=True)],
              f"{spread(ab)} px against {spread(ml)} px"),
        Claim("the alpha-beta filter's predicted points have small errors (fig. 5)", "curves, no figure",
              [p < r for p, r in zip(pred, raw, strict=True)],
              f"one-step prediction RMSE {spread(pred)} px against the raw plots' own error {spread(raw)} px",
              "held when the prediction is closer to the target than a plot is"),
        Claim("the mean filter suppresses glitch noise poorly: it spreads a glitch over several positions (sec. 1.1); "
              "the alpha-beta filter does better",
              "said, no figure", [a < m for a, m in zip(gab, gmm, strict=True)],
              f"with {100 * result['scenario']['glitch']:g} % of plots {result['scenario']['glitch_size']:g} px off: "
              f"alpha-beta {spread(gab)} px, mean {spread(gmm)} px"),
        Claim("alpha = 0.5 and beta = 0.5 are the best choice for the measurements (sec. 1.3)", "alpha = beta = 0.5",
              [a <= b for a, b in zip(fig(tested, "position_rmse"), best_other, strict=True)],
              f"{tested}: {spread(ab)} px; the best of Benedict-Bordner, critically damped and the steady Kalman gains "
              f"at each seed: {spread(best_other)} px"),
        Claim("beta from the gain relation (7) at alpha = 0.5 is 0.5 (sec. 1.3)", "beta = 0.5",
              [abs(bb - 0.5) < 1e-9 or abs(cd - 0.5) < 1e-9],
              f"Benedict-Bordner beta = {bb:.4f}, critically damped beta = {cd:.4f}",
              "a relation, the same on every seed; the relation (7) itself is not printed in the text we have"),
        Claim("alpha-beta needs far fewer additions and multiplications than the Kalman filter (table 1)",
              "table 1 (its figures are not in the text we have)",
              [ab_cost["additions"] < k_cost["additions"] and ab_cost["multiplications"] < k_cost["multiplications"]],
              f"per axis {ab_cost['additions']} additions, {ab_cost['multiplications']} multiplications (0 at "
              f"alpha = beta = 0.5: shifts) against {k_cost['additions']}, {k_cost['multiplications']} and "
              f"{k_cost['divisions']} divisions", "counted on each update, the same on every seed"),
        Claim("alpha-beta gives the target's motion parameters (course and speed) accurately enough for collision "
              "avoidance (abstract)", "no figure", None,
              f"course {spread(fig(tested, 'course_rms_deg'), '.3g')} deg RMS, speed "
              f"{spread(fig(tested, 'speed_rms'))} px/scan RMS",
              "the paper states no accuracy to hold them to"),
    ]


def alphabeta_plot(result, path):
    """The paper's figures: the tracks (truth, plots, filtered), and the position error against time."""
    from kfpga.model.plots import pyplot, save_figure

    plt = pyplot()

    truth, plots, series = result["truth"], result["plots"], result["series"]
    tested = _tested(result["rows"])["filter"]
    fig, (a, b) = plt.subplots(1, 2, figsize=(13, 5.5))
    for t in range(truth.shape[0]):
        a.plot(plots[t, 0], plots[t, 1], ".", ms=2, color="0.6", label="plots" if t == 0 else None)
        a.plot(truth[t, 0], truth[t, 1], "-", lw=0.8, color="k", label="truth" if t == 0 else None)
        a.plot(series[tested][t, 0], series[tested][t, 1], "-", lw=1, color="C0", label=tested if t == 0 else None)
    a.set(title="targets in radar pixel coordinates", xlabel="x (px)", ylabel="y (px)")
    a.set_aspect("equal", adjustable="datalim")
    a.legend(loc="best", fontsize=8)
    for name, style in (("raw plots", ".:"), (next(n for n in series if n.startswith("moving mean")), "-"),
                        ("moving mean, lag removed", "--"), (tested, "-"), ("alpha-beta (steady Kalman gains)", "-"),
                        ("Kalman (time-varying gain)", "-")):
        err = np.sqrt(np.sum((series[name][0] - truth[0]) ** 2, axis=0))
        b.plot(err, style, lw=0.9, ms=2, label=name)
    b.set(title="position error of target 0", xlabel="scan", ylabel="error (px)")
    b.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)




def _add_arguments(parser):
    parser.add_argument("--targets", type=int, default=5, metavar="N", help="targets tracked at once, 1..256 (default: 5)")
    parser.add_argument("--alpha", type=float, default=0.5, metavar="A", help="alpha of the tracker under test "
                                                                            "(default: the paper's 0.5)")
    parser.add_argument("--beta", type=float, metavar="B", help="its beta (default: the paper's 0.5; with --alpha "
                                                              "alone, Benedict-Bordner's alpha^2/(2 - alpha))")
    parser.add_argument("--glitch", type=float, default=0.02, metavar="P",
                        help="share of the plots thrown off in the glitch run, 0..0.5 (default: 0.02)")
    parser.add_argument("--glitch-size", type=float, default=30.0, metavar="PX",
                        help="how far a glitch throws a plot, pixels (default: 30, 15 sigma)")


def _scenario(options):
    from kfpga.model import alphabeta as ab

    beta = options.beta
    if beta is None:
        beta = 0.5 if options.alpha == 0.5 else ab.benedict_bordner(options.alpha)
    try:
        ab.AlphaBetaParams(alpha=options.alpha, beta=beta)
        return AlphaBetaScenario(targets=options.targets, alpha=options.alpha, beta=beta, glitch=options.glitch,
                                 glitch_size=options.glitch_size)
    except ValueError as exc:
        text = str(exc)
        raise UsageError(text if text.startswith("--") else "--alpha/--beta: " + text) from None


def _check(options):
    if not 1 <= options.targets <= 256:
        raise UsageError(f"--targets must be 1..256 (the tracker's limit), not {options.targets}")
    _scenario(options)


def _run(options, seed):
    return alphabeta(_scenario(options), seed=seed)


EVALUATION = Evaluation(
    summary="[Chen]: alpha-beta tracking of radar targets against the moving mean and the Kalman filter",
    description="Targets in straight-line uniform motion in 2-D radar pixel coordinates, with white noise (2 px per "
                "axis) and plots rounded to whole pixels, tracked by the alpha-beta filter (the paper's alpha = beta "
                "= 0.5, Benedict-Bordner and critically damped beta at alpha = 0.5; float and bit-accurate), the "
                "moving mean of 5 plots and the time-varying Kalman filter. Prints the RMSE of position and velocity, "
                "the additions and multiplications per update (the paper's table 1, counted on each filter's "
                "update), and how they compare with the paper.",
    add_arguments=_add_arguments,
    check=_check,
    run=_run,
    table=alphabeta_table,
    summary_json=lambda r: {k: r[k] for k in ("seed", "scenario", "rows", "costs")},
    claims=alphabeta_claims,
    plot=alphabeta_plot,
)
