"""The source documents' own evaluations, rerun (``kfpga evaluate NAME``).

``alpha-beta`` (seeds/004): several radar targets in straight-line uniform motion, in 2-D
radar pixel coordinates with white noise, tracked by the alpha-beta filter (float and
bit-accurate), the moving mean and the Kalman filter; RMSE of position and velocity; the
additions and multiplications per update (the paper's table 1), counted by running each
filter's update on :class:`~kfpga.core.ops.CostOps`.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

__all__ = ["AlphaBetaScenario", "alpha_beta", "alpha_beta_table", "alpha_beta_plot", "NavigationScenario", "tukey53h",
           "tukey53h_table", "tukey53h_findings", "tukey53h_plot", "cubic_smoothing", "sliding_wls", "roll", "roll_table",
           "roll_findings", "roll_plot", "DecelerationScenario", "deceleration_log", "ls_frontend", "ls_frontend_table",
           "ls_frontend_findings", "ls_frontend_plot", "ls_frontend_fixed", "SWITCHED", "BIT_ACCURATE"]


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
    kalman = FilterConfig(params=kp, check_ranges=False)
    costs["Kalman (time-varying gain)"] = update_cost(kalman, "full")
    costs["Kalman (steady-state gain)"] = update_cost(kalman, "steady")
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
    from kfpga.flows.analysis import pyplot

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
    fig.savefig(path, dpi=110)
    plt.close(fig)


# -- seeds/002: the 53H outlier smoother on navigation data -----------------------------------------------


@dataclass(frozen=True)
class NavigationScenario:
    """The paper's data, made up: a ship's INS east and north velocity and heading at 1 Hz.

    A ship at 6 m/s turns from 40 to 130 deg at 0.5 deg/s, speeds up to 9 m/s at 0.02 m/s^2,
    turns back to 70 deg; the sea adds a yaw of 1.5 deg (period 12 s) and a surge of 0.1 m/s
    (period 8 s); the sensors add white noise (0.01 m/s, 0.05 deg). Codes: 1 mm/s and
    0.01 deg. Thresholds from the physical limits (the paper, §3): ``a_max T`` for the
    velocities, ``omega_max T`` for the heading.

    Outliers (seeded): at ``density`` of the samples a run of ``burst`` samples (each run's
    length drawn from it) is offset by ``size * threshold``, a size drawn from ``sizes``, of
    either sign, saturated to the 16-bit codes.
    """

    seconds: int = 3600
    T: float = 1.0
    a_max: float = 0.5  # m/s^2
    omega_max: float = 3.0  # deg/s
    velocity_lsb: float = 0.001  # m/s per code
    heading_lsb: float = 0.01  # deg per code
    density: float = 0.01
    sizes: tuple = (3.0, 10.0, 50.0)
    burst: tuple = (1, 2)
    wls_half: int = 4  # the sliding weighted least-squares window: 2 * half + 1 points
    cubic_window: int = 5

    def __post_init__(self):
        if self.seconds < 16:
            raise ValueError(f"seconds must be at least 16 (the offline 53H needs 16 points), not {self.seconds}")


def navigation_signals(s, rng):
    """``{signal: (truth in codes (float), measured codes, threshold in codes, lsb, unit)}``: the
    noise-free signal and what the sensor gives before any outlier."""
    t = np.arange(s.seconds) * s.T
    n = len(t)

    def ramp(t0, t1, v0, v1):
        return np.clip((t - t0) / (t1 - t0), 0.0, 1.0) * (v1 - v0)

    heading = 40.0 + ramp(600, 780, 40, 130) + ramp(2400, 2520, 130, 70) + 1.5 * np.sin(2 * np.pi * t / 12.0)
    speed = 6.0 + ramp(1200, 1350, 6.0, 9.0) + 0.1 * np.sin(2 * np.pi * t / 8.0)
    psi = np.radians(heading)
    truth = {"east velocity": speed * np.sin(psi) / s.velocity_lsb, "north velocity": speed * np.cos(psi) / s.velocity_lsb,
             "heading": heading / s.heading_lsb}
    noise = {"east velocity": 0.01 / s.velocity_lsb, "north velocity": 0.01 / s.velocity_lsb, "heading": 0.05 / s.heading_lsb}
    from kfpga.model.tukey53h import attitude_threshold, velocity_threshold

    vt = velocity_threshold(s.a_max, s.T, s.velocity_lsb)
    ht = attitude_threshold(s.omega_max, s.T, s.heading_lsb)
    out = {}
    for name, clean in truth.items():
        measured = np.round(clean + rng.normal(0, noise[name], n)).astype(np.int64)
        vel = name != "heading"
        out[name] = (clean, measured, vt if vel else ht, s.velocity_lsb if vel else s.heading_lsb, "m/s" if vel else "deg")
    return out


def cubic_smoothing(x, window=5, order=3):
    """The paper's 5-point cubic smoothing: each point replaced by the cubic fitted by least
    squares to the ``window`` points centred on it, at it; the first and last ``window // 2``
    points by the cubic of the first (last) window, at them. The weights come from the
    least-squares fit itself (``numpy.linalg.pinv`` of the window's Vandermonde matrix: the
    familiar (-3, 12, 17, 12, -3) / 35 in the middle)."""
    x = np.asarray(x, dtype=np.float64)
    h = window // 2
    t = np.arange(-h, h + 1)
    weights = np.linalg.pinv(np.vander(t, order + 1, increasing=True))  # coefficients from samples
    rows = np.vander(t, order + 1, increasing=True) @ weights  # row k: the fit at window position k
    out = np.convolve(x, rows[h][::-1], mode="same")
    out[:h] = rows[:h] @ x[:window]
    out[-h:] = rows[-h:] @ x[-window:]
    return out


def sliding_wls(x, half=4):
    """The sliding weighted least-squares filter: a line fitted to the ``2 half + 1`` points
    centred on each point (fewer at the ends), weights falling linearly with distance,
    ``1 - |k| / (half + 1)``, evaluated at the point. A symmetric window makes that the weighted
    mean, a convolution; at the ends the line is fitted by ``numpy.polyfit``."""
    x = np.asarray(x, dtype=np.float64)
    n = len(x)
    k = np.arange(-half, half + 1)
    w = 1.0 - np.abs(k) / (half + 1)
    out = np.convolve(x, w / w.sum(), mode="same")
    for c in [*range(min(half, n)), *range(max(n - half, half), n)]:
        lo, hi = max(0, c - half), min(n, c + half + 1)
        t = np.arange(lo, hi) - c
        line = np.polyfit(t, x[lo:hi], 1, w=np.sqrt(1.0 - np.abs(t) / (half + 1)))
        out[c] = line[1]  # the line at t = 0
    return out


def _outlier_metrics(out, raw, measured, truth, threshold, lsb, decided=None):
    """Removed (%), false replacements, distorted inliers, RMSE against the noise-free truth (in units).

    The outliers are the samples where ``raw`` (what the filter got) differs from ``measured``
    (the sensor without outliers); one is removed when its output ends within the threshold of
    the truth; a false replacement is an inlier the output changed; a distorted inlier one left
    further than the threshold from the truth.
    """
    sel = slice(None) if decided is None else decided
    out, raw, measured, truth = out[sel], raw[sel], measured[sel], truth[sel]
    bad = raw != measured
    off = np.abs(out - truth) > threshold
    return {"outliers": int(bad.sum()),
            "removed_pct": float(100.0 * np.mean(~off[bad])) if bad.any() else None,
            "false_replacements": int(np.sum((out != raw) & ~bad)),
            "distorted": int(np.sum(off & ~bad)),
            "rmse": float(np.sqrt(np.mean((out - truth) ** 2)) * lsb),
            "rmse_inliers": float(np.sqrt(np.mean((out[~bad] - truth[~bad]) ** 2)) * lsb)}


def tukey53h(scenario=None, *, seed):
    """Run the 53H evaluation: ``{seed, scenario, rows, limits, series}`` (see :func:`tukey53h_table`)."""
    from kfpga.core.config import FilterConfig
    from kfpga.core.fixedmodel import FixedModel
    from kfpga.model import tukey53h as th

    s = NavigationScenario() if scenario is None else scenario
    rng = np.random.default_rng(seed)
    signals = navigation_signals(s, rng)
    rows, series = [], {}
    for i, (name, (truth, measured, threshold, lsb, unit)) in enumerate(signals.items()):
        raw = th.inject_outliers(measured, seed * 16 + i, threshold, density=s.density, sizes=s.sizes, burst=s.burst)
        config = FilterConfig(filter="53h", params=th.Tukey53HParams(threshold=threshold))
        model = FixedModel(config)
        n = len(raw)
        online = model.run(raw).y
        aligned = np.concatenate([online[th.DELAY:], raw[n - th.DELAY:]])  # online: the last 4 not decided yet
        decided = np.arange(n) < n - th.DELAY
        offline = th.offline(raw, run=lambda x, m=model: m.run(x).y)
        float_online = th.reference(config.params, "online", raw)["y"]
        float_aligned = np.concatenate([float_online[th.DELAY:], raw[n - th.DELAY:]])
        methods = {
            "raw (no filter)": (raw.astype(np.float64), None, 0),
            "53H online, bit-accurate": (aligned, decided, th.DELAY),
            "53H online, float": (float_aligned, decided, th.DELAY),
            "53H offline (improved ends), bit-accurate": (offline, None, None),
            f"{s.cubic_window}-point cubic smoothing": (cubic_smoothing(raw, s.cubic_window), None, s.cubic_window // 2),
            f"sliding weighted LS ({2 * s.wls_half + 1} points)": (sliding_wls(raw, s.wls_half), None, s.wls_half),
        }
        for method, (out, where, delay) in methods.items():
            row = {"signal": name, "method": method, "threshold": threshold, "unit": unit, "delay": delay,
                   **_outlier_metrics(out, raw, measured, truth, threshold, lsb, where)}
            rows.append(row)
        series[name] = {"clean": truth * lsb, "raw": raw * lsb, "unit": unit,
                        **{m: out * lsb for m, (out, _, _) in methods.items() if not m.startswith(("raw", "53H online, f"))}}
    return {"seed": seed, "scenario": {k: getattr(s, k) for k in s.__dataclass_fields__}, "rows": rows,
            "limits": _limits(s, signals["east velocity"], seed), "series": series,
            "comparators": _comparators()}


def _limits(s, signal, seed):
    """What 53H removes by burst length, size and density (east velocity): removed %, false replacements."""
    from kfpga.core.config import FilterConfig
    from kfpga.core.fixedmodel import FixedModel
    from kfpga.model import tukey53h as th

    truth, measured, threshold, lsb, _ = signal
    model = FixedModel(FilterConfig(filter="53h", params=th.Tukey53HParams(threshold=threshold)))
    cases = [(f"runs of {b}", 0.01, (10.0,), (b,)) for b in (1, 2, 3, 4)]
    cases += [(f"size {z:g} x threshold", 0.01, (z,), (1,)) for z in (1.2, 2.0, 5.0)]
    cases += [(f"density {100 * d:g} %", d, (10.0,), (1, 2)) for d in (0.005, 0.02, 0.05, 0.1)]
    out = []
    for k, (label, density, sizes, burst) in enumerate(cases):
        raw = th.inject_outliers(measured, seed * 64 + k, threshold, density=density, sizes=sizes, burst=burst)
        y = th.offline(raw, run=lambda x: model.run(x).y)
        out.append({"case": label, **_outlier_metrics(y, raw, measured, truth, threshold, lsb)})
    return out


def _comparators():
    """Comparators and other operations per sample of the online 53H, counted on its update."""
    from kfpga.core.config import FilterConfig
    from kfpga.core.ops import CostOps, update_cost
    from kfpga.model import tukey53h as th

    ops = CostOps({})
    values = [ops.input(0, th.FLAG) for _ in range(5)]
    th.median5(ops, *values)
    m5 = dict(ops.counts)
    ops = CostOps({})
    th.median3(ops, *values[:3])
    return {"median of 5": m5, "median of 3": dict(ops.counts), "whole update": update_cost(FilterConfig(filter="53h"),
                                                                                            "online")}


def tukey53h_table(result):
    """The report: the methods on each signal, what 53H cannot remove, and the paper's claims."""
    s = result["scenario"]
    lines = [f"seed {result['seed']}: {s['seconds']} s at {1 / s['T']:g} Hz; outliers at {100 * s['density']:g} % of the "
             f"samples, runs of {'/'.join(map(str, s['burst']))}, sizes {'/'.join(f'{z:g}' for z in s['sizes'])} x threshold",
             f"thresholds: velocity a_max*T = {s['a_max']:g} m/s^2 x {s['T']:g} s; heading omega_max*T = "
             f"{s['omega_max']:g} deg/s x {s['T']:g} s", "",
             f"{'signal':<15} {'method':<43} {'outliers':>8} {'removed':>8} {'false':>6} {'distorted':>9} "
             f"{'RMSE':>9} {'inliers':>9} {'delay':>6}"]
    for r in result["rows"]:
        removed = "" if r["method"].startswith("raw") else f"{r['removed_pct']:.1f} %"
        delay = "offline" if r["delay"] is None else f"{r['delay']}"
        false = "all" if "53H" not in r["method"] and not r["method"].startswith("raw") else str(r["false_replacements"])
        lines.append(f"{r['signal']:<15} {r['method']:<43} {r['outliers']:>8} {removed:>8} {false:>6} "
                     f"{r['distorted']:>9} {r['rmse']:>9.4f} {r['rmse_inliers']:>9.4f} {delay:>6}")
    lines += ["", "RMSE against the noise-free signal in m/s or deg (all samples, and inliers only); removed: outliers "
              "ending within the threshold of the noise-free value; false: inliers changed (a smoother changes all); "
              "distorted: inliers left further than the threshold from the noise-free value; delay in samples.", "",
              "what 53H removes (offline, bit-accurate, east velocity):",
              f"{'case':<26} {'outliers':>8} {'removed':>8} {'false':>6} {'distorted':>9}"]
    for r in result["limits"]:
        lines.append(f"{r['case']:<26} {r['outliers']:>8} {r['removed_pct']:>7.1f} % {r['false_replacements']:>6} "
                     f"{r['distorted']:>9}")
    c = result["comparators"]
    lines += ["", f"per sample: median of 5 {c['median of 5']['comparisons']} comparators, median of 3 "
              f"{c['median of 3']['comparisons']}, the whole update {c['whole update']['comparisons']} comparisons "
              f"(one the channel's first-sample flag), {c['whole update']['additions']} additions, "
              f"{c['whole update']['multiplications']} multiplications", "", "against the paper:"]
    lines += [f"  {line}" for line in tukey53h_findings(result)]
    return "\n".join(lines)


def tukey53h_findings(result):
    """The paper's conclusions (§3), checked on these figures."""
    rows = {(r["signal"], r["method"]): r for r in result["rows"]}
    signals = list(dict.fromkeys(r["signal"] for r in result["rows"]))
    methods = list(dict.fromkeys(r["method"] for r in result["rows"]))
    h53 = next(m for m in methods if m.startswith("53H offline"))
    cubic = next(m for m in methods if "cubic" in m)
    wls = next(m for m in methods if "weighted" in m)

    def worst(method, key, pick=min):
        return pick(rows[(sig, method)][key] for sig in signals)

    limits = {r["case"]: r for r in result["limits"]}
    all_removed = worst(h53, "removed_pct") == 100.0 and worst(h53, "false_replacements", max) == 0
    return [
        f"53H removes every outlier and keeps the data (its figs. 5-6): {worst(h53, 'removed_pct'):.1f} % removed at "
        f"worst, {worst(h53, 'false_replacements', max)} false replacements: "
        + ("confirmed" if all_removed else "not confirmed") + " for single outliers and runs of 2; runs of 3 or "
        f"more pass the median of 5 ({limits['runs of 3']['removed_pct']:.0f} % of runs of 3 removed) and spread to "
        f"their neighbours ({limits['runs of 3']['false_replacements']} false replacements).",
        f"5-point cubic smoothing does not remove large outliers and distorts (figs. 5-6): {worst(cubic, 'removed_pct'):.1f} "
        f"% removed at worst, {worst(cubic, 'distorted', max)} inliers distorted: confirmed (its weights spread an "
        "outlier onto 4 neighbours).",
        f"the sliding least-squares filter only damps large outliers: {worst(wls, 'removed_pct'):.1f} % removed at "
        f"worst, {worst(wls, 'distorted', max)} inliers distorted: confirmed; the paper says it does not distort, "
        "which holds for small outliers only.",
        f"the delay: 4 samples online, as the paper says (at 1 Hz, 4 s); offline, none. East velocity, inliers only: "
        f"53H {rows[(signals[0], h53)]['rmse_inliers']:.4f} m/s, the sensor's own noise, left as measured, against "
        f"{rows[(signals[0], cubic)]['rmse_inliers']:.4f} (cubic) and {rows[(signals[0], wls)]['rmse_inliers']:.4f} (LS): "
        "a smoother spreads every outlier over its window.",
        "the paper's data (11 h of sea trials) is not available; the signals here are synthetic, with the outliers "
        "known, which the paper's figures cannot give.",
    ]


def tukey53h_plot(result, path):
    """The paper's figs. 5-6: east and north velocity before and after each method."""
    from kfpga.flows.analysis import pyplot

    plt = pyplot()

    names = ["east velocity", "north velocity"]
    fig, axes = plt.subplots(len(names), 1, figsize=(13, 8), sharex=True)
    for ax, name in zip(axes, names, strict=True):
        s = result["series"][name]
        t = np.arange(len(s["raw"]))
        ax.plot(t, s["raw"], color="0.75", lw=0.6, label="measured (with outliers)")
        for method, colour in ((next(m for m in s if "cubic" in m), "C1"), (next(m for m in s if "weighted" in m), "C2"),
                               (next(m for m in s if m.startswith("53H offline")), "C0")):
            ax.plot(t, s[method], lw=0.8, color=colour, label=method)
        ax.plot(t, s["clean"], "k--", lw=0.6, label="clean")
        lo, hi = float(np.min(s["clean"])), float(np.max(s["clean"]))
        ax.set_ylim(lo - 0.3 * (hi - lo) - 0.5, hi + 0.3 * (hi - lo) + 0.5)
        ax.set(title=f"{name}: outliers clipped by the axes", ylabel=f"{name} ({s['unit']})")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=5, fontsize=8)
    axes[-1].set_xlabel(f"time (s), seed {result['seed']}")
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    fig.savefig(path, dpi=110)
    plt.close(fig)


# -- seeds/000: the ship-roll interval predictor ------------------------------------------------------------

#: The paper's figures (its 480 samples): prediction RMSE before and after, and the requirement.
ROLL_PAPER = {"basic": 0.3935, "improved": 0.1173, "requirement": 0.2}
#: The points of the square-root predictor shown with its figures.
_ROLL_SQRT_POINTS = ("x1", "x2", "x3", "e", "d", "s", "rs", "f", "kn", "k", "cs", "sqs")
#: The fading factors of the sweep.
ROLL_FADING = (1.0, 1.5, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 1000.0)

_ROLL_FORMS = (
    ("basic (predict, then update)", {"improved": False}),
    ("update then predict, s = 1", {"improved": True, "fading": False, "sqrt": False}),
    ("update then predict, fading s", {"improved": True, "fading": True, "sqrt": False}),
    ("improved: + square root (the paper's)", {"improved": True, "fading": True, "sqrt": True}),
)


def roll(*, seed, samples=480, series=None, params=None):
    """The roll evaluation: prediction RMSE of each form on the paper's table 1 and on a
    synthetic series (or ``series``: a user's ``(name, roll array)``), the sweep over s, and
    the series the plot draws."""
    from kfpga.model import roll as rp

    params = rp.RollParams() if params is None else params
    sets = {}
    _, table = rp.table1()
    sets["table 1 (32 samples)"] = table
    if series is not None:
        sets[series[0]] = np.asarray(series[1], dtype=np.float64)
    else:
        _, y, _ = rp.synthetic_roll(samples, seed, T=params.T)
        sets[f"synthetic ({samples} samples, seed {seed})"] = y
    rows, sweep, plot = [], [], {}
    for data, z in sets.items():
        for name, opts in _ROLL_FORMS:
            p = rp.predict(z, params, **opts)
            err, count = rp.prediction_rmse(z, p)
            rows.append({"data": data, "form": name, "rmse_deg": err, "predictions": count})
            plot.setdefault(data, {"roll": z})[name] = p
        for s in ROLL_FADING:
            from dataclasses import replace

            p = rp.predict(z, replace(params, s=s))
            sweep.append({"data": data, "s": s, "rmse_deg": rp.prediction_rmse(z, p)[0]})
    # the bit-accurate predictor (the core's integers, default formats) against float from the
    # same start, and both forms over word lengths on the longer series
    from kfpga.core.config import FilterConfig

    config = FilterConfig(filter="roll", params=params)
    fixed = []
    for data, z in sets.items():
        pred, overflowed, not_pd = rp.predict_fixed(z, config, check=True)
        same = rp.predict_same_start(z, params)
        diff = (pred - same)[:-2]
        fixed.append({"data": data, "rmse_fixed_deg": rp.prediction_rmse(z, pred)[0],
                      "rmse_float_deg": rp.prediction_rmse(z, same)[0], "max_from_float_deg": float(np.max(np.abs(diff))),
                      "rms_from_float_deg": float(np.sqrt(np.mean(diff ** 2))), "overflowed": overflowed,
                      "not_positive_definite": not_pd, "updates": len(z)})
        plot[data]["bit-accurate (square root, default formats)"] = pred
    longest = max(sets, key=lambda d: len(sets[d]))
    words = rp.word_sweep(sets[longest], params)
    return {"seed": seed, "params": {"T": params.T, "q": params.q, "R": params.R, "s": params.s,
                                     "P0": [list(r) for r in params.P0], "lsb": params.lsb},
            "rows": rows, "sweep": sweep, "series": plot, "formats": {k: str(v) for k, v in config.formats.items()
                                                                          if k in _ROLL_SQRT_POINTS},
            "fixed": fixed, "words": words, "words_data": longest}


def roll_table(result):
    w = max(34, *(len(r["data"]) for r in result["rows"]))
    lines = [f"T = {result['params']['T']:g} s, two filters on alternate samples, each predicting 2 samples "
             f"(1 s) ahead; Q = {result['params']['q']:g} I, R = {result['params']['R']:g}, s = {result['params']['s']:g}, "
             "P0 the paper's (all 10s: singular, so the square root starts from A P0 A' + Q); RMSE of the prediction "
             "against the sample it predicts", "",
             f"{'data':<{w}} {'form':<40} {'RMSE (deg)':>10} {'predictions':>12}"]
    for r in result["rows"]:
        lines.append(f"{r['data']:<{w}} {r['form']:<40} {r['rmse_deg']:>10.4f} {r['predictions']:>12}")
    lines += ["", "fading factor s (improved form):", f"{'data':<{w}} " + "".join(f"{s:>8g}" for s in ROLL_FADING)]
    for data in dict.fromkeys(r["data"] for r in result["sweep"]):
        lines.append(f"{data:<{w}} " + "".join(f"{r['rmse_deg']:>8.4f}" for r in result["sweep"] if r["data"] == data))
    lines += ["", "bit-accurate predictor (the core's integers; formats "
              + ", ".join(f"{k} {v}" for k, v in result["formats"].items()) + "), against float from the same start "
              "(each filter from x = 0 and A P0 A' + Q):",
              f"{'data':<{w}} {'RMSE fixed':>10} {'RMSE float':>10} {'max |fixed - float|':>20} "
              f"{'rms':>9} {'overflows':>9} {'not PD':>7}"]
    for r in result["fixed"]:
        lines.append(f"{r['data']:<{w}} {r['rmse_fixed_deg']:>10.4f} {r['rmse_float_deg']:>10.4f} "
                     f"{r['max_from_float_deg']:>20.6f} {r['rms_from_float_deg']:>9.6f} {r['overflowed']:>9} "
                     f"{r['not_positive_definite']:>7}")
    lines += ["", f"word lengths ({result['words_data']}): updates whose covariance is not positive definite, of "
              f"{result['words'][0].get('updates', '?')} (square root: a zero on D's diagonal; plain: an eigenvalue "
              "of P <= 0), and the RMSE; registers of the covariance path with F fraction bits, its multiplier "
              "operands (gains, rotations) B bits wide",
              f"{'form':<7} {'F':>3} {'width':>6} " + "".join(f"{'B=' + str(b):>15}" for b in _word_bits(result))]
    for (form, frac), cells in _word_grid(result).items():
        width = next((c["covariance_width"] for c in cells.values() if "covariance_width" in c), None)
        line = f"{form:<7} {frac:>3} {width if width else '-':>6} "
        for b in _word_bits(result):
            c = cells.get(b, {})
            line += (f"{c['not_positive_definite']:>5} {c['rmse_deg']:>9.4g}" if "rmse_deg" in c else f"{'(> 62 bits)':>15}")
        lines.append(line)
    lines += ["", "against the paper:"] + [f"  {line}" for line in roll_findings(result)]
    return "\n".join(lines)


def _word_bits(result):
    return sorted({r["operand_bits"] for r in result["words"]})


def _word_grid(result):
    grid = {}
    for r in result["words"]:
        grid.setdefault((r["form"], r["register_frac"]), {})[r["operand_bits"]] = r
    return grid


def roll_findings(result):
    rows = {(r["data"], r["form"]): r for r in result["rows"]}
    datas = list(dict.fromkeys(r["data"] for r in result["rows"]))
    basic, best = _ROLL_FORMS[0][0], _ROLL_FORMS[3][0]
    plain, fading = _ROLL_FORMS[1][0], _ROLL_FORMS[2][0]
    out = []
    for data in datas:
        b, i = rows[(data, basic)]["rmse_deg"], rows[(data, best)]["rmse_deg"]
        out.append(f"{data}: {b:.4f} deg before, {i:.4f} after (the paper, on its 480 samples: {ROLL_PAPER['basic']}, "
                   f"{ROLL_PAPER['improved']}): the improvement {'confirmed' if i < b else 'not confirmed'}; the "
                   f"requirement < {ROLL_PAPER['requirement']} deg {'met' if i < ROLL_PAPER['requirement'] else 'not met'}. "
                   f"Of the gain, the order of update and prediction gives {b - rows[(data, plain)]['rmse_deg']:.4f}, "
                   f"the fading memory {rows[(data, plain)]['rmse_deg'] - rows[(data, fading)]['rmse_deg']:.4f}, the "
                   f"square root {rows[(data, fading)]['rmse_deg'] - i:+.4f} (in float64 it changes no figure: it is "
                   "there for rounding, which float64 does not show).")
    out += ["table 1 has 32 of the paper's 480 samples (it says 40, prints 32): 26 predictions, from 0.5 s to 16 s, "
            "less than two roll periods. It confirms the direction of the gain and the requirement on them, not the "
            "paper's figures, which need its 480 samples; the synthetic series stands in for them, with its noise known.",
            _fading_finding(result), _fixed_finding(result), _word_finding(result)]
    return out


def _fixed_finding(result):
    parts = [f"{r['data']}: RMSE {r['rmse_fixed_deg']:.4f} deg (float {r['rmse_float_deg']:.4f}), at most "
             f"{r['max_from_float_deg']:.5f} deg from float, {r['overflowed']} overflows, "
             f"{r['not_positive_definite']} covariances not positive definite" for r in result["fixed"]]
    return ("fixed point: the square-root predictor in the core's integers at its default formats: " + "; ".join(parts)
            + ". Its error is far below the prediction error itself.")


def _word_finding(result):
    grid = _word_grid(result)

    def fails(form):
        return sorted({r["operand_bits"] for r in result["words"] if r["form"] == form and r.get("not_positive_definite")})

    root, plain = fails("sqrt"), fails("plain")
    plain_ok = sorted({r["operand_bits"] for r in result["words"] if r["form"] == "plain" and "rmse_deg" in r
                       and not r["not_positive_definite"]})
    widths = {form: min(c["covariance_width"] for (f, _), cells in grid.items() if f == form
                        for c in cells.values() if "covariance_width" in c) for form in ("sqrt", "plain")}
    text = (f"word lengths: the square-root form keeps its covariance positive definite at every word length of "
            f"the sweep, down to {widths['sqrt']}-bit D and {min(_word_bits(result))}-bit operands"
            if not root else f"word lengths: the square-root form loses positive definiteness with operands of "
            f"{', '.join(map(str, root))} bits")
    if plain:
        text += (f"; the plain form, whose P needs {widths['plain']} bits for its range alone, loses it with gains of "
                 f"{max(plain)} bits and fewer: P = P - K P[0,:] subtracts two numbers near p11 (the gain of the "
                 "angle is within 1e-6 of 1 at s = 100), and the gain's rounding, times p11 (up to 3e8 codes^2), "
                 "is far larger than the difference")
        if plain_ok:
            text += f"; it holds from {min(plain_ok)}-bit gains on (two embedded multipliers per product)"
    return text + ". The paper's claim that the square root keeps the covariance positive definite is confirmed."


def _fading_finding(result):
    """What the sweep over s says of the paper's s = 100 (on the data sets of the run)."""
    parts = []
    for data in dict.fromkeys(r["data"] for r in result["sweep"]):
        by_s = {r["s"]: r["rmse_deg"] for r in result["sweep"] if r["data"] == data}
        best = min(by_s, key=by_s.get)
        parts.append(f"{data}: s = 100 gives {by_s[100.0]:.4f} deg, the best s of the sweep ({best:g}) "
                     f"{by_s[best]:.4f}, no fading (s = 1) {by_s[1.0]:.4f}")
    return "fading memory: " + "; ".join(parts) + "."


def roll_plot(result, path):
    """The paper's figs. 4-5: the roll and its predictions, and the prediction errors."""
    from kfpga.flows.analysis import pyplot

    plt = pyplot()

    data = next(d for d in result["series"] if not d.startswith("table"))
    s = result["series"][data]
    z = s["roll"]
    t = np.arange(len(z)) * result["params"]["T"]
    fig = plt.figure(figsize=(13, 11))
    a = fig.add_subplot(3, 1, 1)
    b = fig.add_subplot(3, 1, 2, sharex=a)
    c = fig.add_subplot(3, 1, 3)
    a.plot(t, z, "k-", lw=1.0, label="measured roll S")
    for name, style in ((_ROLL_FORMS[0][0], ":"), (_ROLL_FORMS[3][0], "-.")):
        # the prediction made at sample n, drawn at the time it predicts (n + 2)
        a.plot(t[2:], s[name][:-2], style, lw=1.0, label=f"predicted, {name}")
        b.plot(t[2:], s[name][:-2] - z[2:], style, lw=1.0, label=f"error, {name}")
    a.set(title=f"roll angle and its 1 s prediction ({data})", ylabel="roll (deg)")
    b.set(title="prediction error", xlabel="time (s)", ylabel="error (deg)")
    b.axhline(ROLL_PAPER["requirement"], color="0.6", lw=0.6)
    b.axhline(-ROLL_PAPER["requirement"], color="0.6", lw=0.6)
    a.legend(loc="upper right", fontsize=8)
    b.legend(loc="upper right", fontsize=8)
    for (form, frac), cells in _word_grid(result).items():
        bits = [bb for bb in sorted(cells) if "rmse_deg" in cells[bb]]
        share = [100.0 * cells[bb]["not_positive_definite"] / cells[bb]["updates"] for bb in bits]
        c.plot(bits, share, "o-" if form == "sqrt" else "s--", label=f"{'square root' if form == 'sqrt' else 'plain'}, "
                                                                     f"F = {frac}")
    c.set(title=f"covariance not positive definite ({result['words_data']})", xlabel="multiplier operand bits B",
          ylabel="% of updates")
    c.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# -- seeds/003: the least-squares front end ---------------------------------------------------------------


@dataclass(frozen=True)
class DecelerationScenario:
    """The patent's fig. 4: a ship at constant speed, decelerating at a constant rate to a stop.

    ``v0`` m/s until ``t0``, then ``-decel`` m/s^2 to 0, then stopped, sampled every ``T`` for
    ``seconds``; the speed log adds white noise of ``sigma_v``; the both-observed filter gets an
    accelerometer with noise ``sigma_a``. Responsiveness: the onset delay (after the deceleration
    starts, how much later than the truth an estimate is ``drop`` m/s below ``v0``), the lag in
    the ramp, and the undershoot after the stop (the error averaged over ``average`` samples,
    centred, so that it is the estimate's own and not its noise). ``window``: the moving
    average's length.
    """

    seconds: int = 700
    T: float = 1.0
    v0: float = 5.0
    t0: float = 200.0
    decel: float = 0.05
    sigma_v: float = 0.1
    sigma_a: float = 0.01
    drop: float = 0.25
    average: int = 21
    window: int = 10

    @property
    def t_stop(self):
        return self.t0 + self.v0 / self.decel


def deceleration_log(s, seed):
    """``(t, true speed, speed log, accelerometer)`` of the scenario ``s``, the noise seeded."""
    rng = np.random.default_rng([seed, 3])
    t = np.arange(s.seconds) * s.T
    truth = np.where(t < s.t0, s.v0, np.maximum(s.v0 - s.decel * (t - s.t0), 0.0))
    accel = np.where((t >= s.t0) & (t < s.t_stop), -s.decel, 0.0)
    return t, truth, truth + rng.normal(0, s.sigma_v, len(t)), accel + rng.normal(0, s.sigma_a, len(t))


def ls_frontend(scenario=None, *, seed, params=None):
    """The patent's four curves on the deceleration scenario: ``{seed, scenario, params, rows, series}``."""
    from kfpga.model import lsfront as ls

    s = DecelerationScenario() if scenario is None else scenario
    params = ls.LSFrontParams(T=s.T, r=s.sigma_v ** 2) if params is None else params
    t, truth, v, a = deceleration_log(s, seed)
    fed = ls.lsfront(v, params)
    fixed = ls_frontend_fixed(v, params)
    curves = {
        "LS-fed Kalman (the patent)": fed["velocity"],
        "Kalman, velocity and acceleration observed": ls.kalman_va(v, params, a=a, r_a=s.sigma_a ** 2)["velocity"],
        "Kalman, velocity only": ls.kalman_va(v, params)["velocity"],
        f"moving average ({s.window} samples)": ls.moving_average(v, s.window),
        SWITCHED: fixed.pop("float"),
        BIT_ACCURATE: fixed.pop("fixed"),
    }
    cruise = (t >= 50) & (t < s.t0)
    ramp = (t >= s.t0 + 20) & (t < s.t_stop - 10)
    stopped = t >= s.t_stop + 100
    rows = []
    for name, est in curves.items():
        e = est - truth
        mean_e = np.convolve(e, np.ones(s.average) / s.average, mode="same")
        below = np.flatnonzero((t >= s.t0) & (est <= s.v0 - s.drop))
        onset = float(t[below[0]] - (s.t0 + s.drop / s.decel)) if below.size else None
        after = (t >= s.t_stop) & (t < s.t_stop + 100)
        rows.append({"filter": name, "rmse_cruise": float(np.sqrt(np.mean(e[cruise] ** 2))),
                     "rmse_stopped": float(np.sqrt(np.mean(e[stopped] ** 2))),
                     "rmse_ramp": float(np.sqrt(np.mean(e[ramp] ** 2))), "onset_delay_s": onset,
                     "lag_s": float(np.mean(e[ramp]) / s.decel),
                     "undershoot": float(max(0.0, -np.min(mean_e[after])))})
    rows.insert(0, {"filter": "speed log (raw)", "rmse_cruise": float(np.sqrt(np.mean((v - truth)[cruise] ** 2))),
                    "rmse_stopped": float(np.sqrt(np.mean((v - truth)[stopped] ** 2))),
                    "rmse_ramp": float(np.sqrt(np.mean((v - truth)[ramp] ** 2))), "onset_delay_s": None, "lag_s": None,
                    "undershoot": None})
    windows = np.bincount(fed["Ns"], minlength=max(params.windows) + 1)
    return {"seed": seed, "scenario": {k: getattr(s, k) for k in s.__dataclass_fields__},
            "params": {"T": params.T, "q": params.q, "r": params.r, "table": [list(r) for r in params.table]},
            "rows": rows, "windows": {int(n): int(c) for n, c in enumerate(windows) if c}, "fixed": fixed,
            "series": {"t": t, "truth": truth, "raw": v, **curves, "Ns": fed["Ns"]}}


#: The rows of the front end's fixed-point form: in float, and in the core's integers.
SWITCHED = "LS-fed, a steady-state gain per mode (float)"
BIT_ACCURATE = "LS-fed, bit-accurate (the core's integers)"


def ls_frontend_fixed(v, params):
    """The front end in the core's integers on the speed log ``v`` (m/s, ADC codes of
    ``params.lsb``) and the same switched steady-state filter in float: both estimates (m/s),
    their distance, the formats, the overflowed samples and the samples whose window differs."""
    from kfpga.core.config import FilterConfig
    from kfpga.core.fixedmodel import FixedModel
    from kfpga.model import lsfront as ls
    from kfpga.model.scenarios import adc_codes

    config = FilterConfig(filter="ls-frontend", params=params)
    codes = adc_codes(np.asarray(v) / params.lsb)
    run = FixedModel(config).run(codes)
    ref = ls.switched(codes, params)
    fixed = run.outputs["velocity"] * config.formats["x1"].lsb * params.lsb
    flt = ref["velocity"] * params.lsb
    diff = fixed - flt
    accel = (run.outputs["accel"] * config.formats["x2"].lsb - ref["accel"]) * params.lsb / params.T
    return {"fixed": fixed, "float": flt, "formats": {k: str(f) for k, f in config.formats.items()},
            "max_from_float": float(np.max(np.abs(diff))), "rms_from_float": float(np.sqrt(np.mean(diff ** 2))),
            "accel_max_from_float": float(np.max(np.abs(accel))), "overflows": int(run.overflow.sum()),
            "window_differs": int(np.sum(run.outputs["ns"] != ref["ns"])), "samples": len(codes),
            "gains": {("m = 1" if n == 0 else f"Ns = {n}"): [[float(g) for g in row] for row in k]
                      for n, k in ls.mode_gains(params).items()}}


def ls_frontend_table(result):
    s = result["scenario"]
    table = ", ".join(f"|innovation| < {t:g}: {n}" for t, n in result["params"]["table"])
    lines = [f"seed {result['seed']}: {s['v0']:g} m/s, decelerating at {s['decel']:g} m/s^2 from {s['t0']:g} s to a stop "
             f"at {s['t0'] + s['v0'] / s['decel']:g} s; speed log noise {s['sigma_v']:g} m/s, accelerometer "
             f"{s['sigma_a']:g} m/s^2 (the both-observed filter only); windows Ns: {table}", "",
             f"{'filter':<46} {'RMSE cruise':>11} {'RMSE stopped':>12} {'RMSE ramp':>10} {'onset (s)':>9} {'lag (s)':>8} "
             f"{'undershoot':>10}"]
    for r in result["rows"]:
        def fmt(value, spec):
            return "" if value is None else format(value, spec)
        lines.append(f"{r['filter']:<46} {r['rmse_cruise']:>11.4f} {r['rmse_stopped']:>12.4f} {r['rmse_ramp']:>10.4f} "
                     f"{fmt(r['onset_delay_s'], '.0f'):>9} {fmt(r['lag_s'], '.2f'):>8} {fmt(r['undershoot'], '.4f'):>10}")
    used = ", ".join(f"{n}: {c}" for n, c in result["windows"].items())
    lines += ["", "RMSE in m/s: cruise from 50 s to the deceleration, stopped from 100 s after the stop, ramp inside the "
              f"deceleration; onset: how much later than the truth the estimate is {s['drop']:g} m/s below the cruise "
              f"speed; lag: the mean error in the ramp over the deceleration; undershoot: below zero after the stop, the "
              f"error averaged over {s['average']} samples (m/s). Samples per window Ns (0: raw velocity, m = 1): {used}",
              "", ls_frontend_fixed_text(result["fixed"]), "",
              "against the patent:"] + [f"  {line}" for line in ls_frontend_findings(result)]
    return "\n".join(lines)


def ls_frontend_fixed_text(fixed):
    gains = "; ".join(f"{mode}: K = {k}".replace("], [", "; ") for mode, k in
                      ((m, [[round(g, 4) for g in row] for row in k]) for m, k in fixed["gains"].items()))
    return (f"fixed point (the core's integers; formats {', '.join(f'{k} {v}' for k, v in fixed['formats'].items())}): "
            f"the running sums exact, the slope one product by 2^s/D per window, the line's end value S0/n + slope "
            f"(n-1)/2; at most {fixed['max_from_float']:.5f} m/s from the same filter in float "
            f"({fixed['rms_from_float']:.5f} rms), the acceleration at most {fixed['accel_max_from_float']:.6f} m/s^2; "
            f"{fixed['overflows']} overflows, the window different from float's in {fixed['window_differs']} of "
            f"{fixed['samples']} samples. Its steady-state gains (velocity, acceleration per sample) per mode: {gains}.")


def ls_frontend_findings(result):
    rows = {r["filter"]: r for r in result["rows"]}
    fed = rows["LS-fed Kalman (the patent)"]
    both = rows["Kalman, velocity and acceleration observed"]
    vonly = rows["Kalman, velocity only"]
    mean = next(r for n, r in rows.items() if n.startswith("moving average"))
    sw = rows[SWITCHED]
    quiet = fed["rmse_cruise"] < min(vonly["rmse_cruise"], mean["rmse_cruise"])
    quick = abs(fed["lag_s"]) < abs(mean["lag_s"])
    at_changes = fed["onset_delay_s"] <= vonly["onset_delay_s"] and fed["undershoot"] <= vonly["undershoot"]
    verdict = ("confirmed" if quick and at_changes else
               "in the ramp, against the moving average, confirmed; at the changes not: the long window's slope keeps the "
               "old acceleration, and R trusts it" if quick else "not confirmed")
    return [
        f"high noise suppression (its claim): at constant speed {fed['rmse_cruise']:.4f} m/s against "
        f"{vonly['rmse_cruise']:.4f} (velocity only) and {mean['rmse_cruise']:.4f} (moving average): "
        + ("confirmed" if quiet else "not confirmed") + "; stopped "
        f"{fed['rmse_stopped']:.4f} against {vonly['rmse_stopped']:.4f} and {mean['rmse_stopped']:.4f}.",
        f"high responsiveness: a lag of {fed['lag_s']:.2f} s in the deceleration against the moving average's "
        f"{mean['lag_s']:.2f} s; the onset seen "
        f"{fed['onset_delay_s']:.0f} s after the truth (velocity only {vonly['onset_delay_s']:.0f} s, moving average "
        f"{mean['onset_delay_s']:.0f} s); after the stop it undershoots by {fed['undershoot']:.3f} m/s (velocity only "
        f"{vonly['undershoot']:.3f}, both observed {both['undershoot']:.3f}): " + verdict + ".",
        f"close to the filter that observes both (its fig. 4, curve x1): RMSE in the ramp {fed['rmse_ramp']:.4f} against "
        f"{both['rmse_ramp']:.4f} m/s, at constant speed {fed['rmse_cruise']:.4f} against {both['rmse_cruise']:.4f}; "
        "without an accelerometer.",
        f"its fixed-point form (a steady-state gain for each mode, switched as the window changes): in float, RMSE "
        f"{sw['rmse_cruise']:.4f} m/s at constant speed and {sw['rmse_ramp']:.4f} in the ramp, an undershoot of "
        f"{sw['undershoot']:.3f} m/s (the patent's time-varying filter: {fed['rmse_cruise']:.4f}, {fed['rmse_ramp']:.4f}, "
        f"{fed['undershoot']:.3f}); in the core's integers at most {result['fixed']['max_from_float']:.4f} m/s from "
        "that float filter.",
        "the patent gives curves, not figures; the scenario's numbers (speed, rate, noise) are this code's own.",
    ]


def ls_frontend_plot(result, path):
    """The patent's fig. 4: the velocity estimates through the deceleration, and their errors."""
    from kfpga.flows.analysis import pyplot

    plt = pyplot()

    s = result["series"]
    t = s["t"]
    names = [r["filter"] for r in result["rows"][1:]]
    fig, (a, b) = plt.subplots(2, 1, figsize=(13, 8), sharex=True)
    a.plot(t, s["raw"], ".", ms=1.5, color="0.7", label="speed log")
    a.plot(t, s["truth"], "k--", lw=0.8, label="true speed")
    for name in names:
        style = "--" if name == BIT_ACCURATE else "-"  # on top of its float form
        a.plot(t, s[name], style, lw=1.0, label=name)
        b.plot(t, s[name] - s["truth"], style, lw=0.8, label=name)
    a.set(title=f"a ship decelerating to a stop (seed {result['seed']})", ylabel="speed (m/s)")
    b.set(title="estimate - true speed", xlabel="time (s)", ylabel="error (m/s)", ylim=(-0.3, 0.3))
    a.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
