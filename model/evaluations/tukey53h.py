"""The 53H smoother's source document, rerun: ``kfpga evaluate tukey53h`` (seeds/002).

A ship's INS east and north velocity and heading, with seeded outliers, smoothed by the online
and the offline 53H (bit-accurate), the 5-point cubic smoothing and a sliding weighted
least-squares filter: outliers removed, false replacements, distortion, RMSE and delay.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kfpga.core.spec import Evaluation


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
    from kfpga.core.plots import pyplot, save_figure

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
    save_figure(fig, path, dpi=110)


# -- seeds/000: the ship-roll interval predictor ------------------------------------------------------------

#: The paper's figures (its 480 samples): prediction RMSE before and after, and the requirement.


EVALUATION = Evaluation(
    summary="seeds/002: the 53H outlier smoother on a ship's navigation data against 5-point cubic smoothing and "
            "sliding weighted least squares",
    description="A ship's INS east and north velocity and heading at 1 Hz for an hour (synthetic: turns, a speed "
                "change, sea-induced yaw and surge, sensor noise), with seeded outliers of several sizes, single and "
                "in runs of 2, smoothed by the online and the offline 53H (bit-accurate; thresholds a_max*T and "
                "omega_max*T), the 5-point cubic smoothing and a sliding weighted least-squares filter. Prints, per "
                "signal and method, the outliers removed, false replacements, distorted inliers, RMSE and delay; "
                "what 53H cannot remove (runs of 3 and more, dense outliers); and how it compares with the paper.",
    add_arguments=lambda parser: None,
    run=lambda options, seed: tukey53h(seed=seed),
    table=tukey53h_table,
    summary_json=lambda r: ({k: r[k] for k in ("seed", "scenario", "rows", "limits", "comparators")}
                            | {"findings": tukey53h_findings(r)}),
    plot=tukey53h_plot,
)
