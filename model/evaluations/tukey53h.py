"""The 53H smoother's source document, rerun: ``kfpga evaluate tukey53h`` ([Lu]).

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
    0.01 deg (a full turn of the heading is 36000 codes), latitude and longitude from 59.9 deg N,
    10.7 deg E in 1e-7 deg (32-bit samples, INS position noise 1 m). Thresholds from the
    physical limits (the paper, §3): ``a_max T`` for the velocities, ``omega_max T`` for the
    heading, ``V_max T / R`` for latitude and longitude.

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
    position_lsb: float = 1e-7  # deg per code of latitude and longitude (32-bit samples)
    v_max: float = 12.0  # m/s: the position's threshold V_max T / R
    position_noise: float = 1.0  # m
    density: float = 0.01
    sizes: tuple = (3.0, 10.0, 50.0)
    burst: tuple = (1, 2)
    wls_half: int = 4  # the sliding weighted least-squares window: 2 * half + 1 points
    cubic_window: int = 5

    def __post_init__(self):
        if self.seconds < 16:
            raise ValueError(f"seconds must be at least 16 (the offline 53H needs 16 points), not {self.seconds}")


def navigation_signals(s, rng):
    """``{signal: (truth in codes (float), measured codes, threshold in codes, lsb, unit, params)}``:
    the noise-free signal, what the sensor gives before any outlier, and the smoother's other
    parameters (the positions' 32-bit samples)."""
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
    from kfpga.model.tukey53h import attitude_threshold, position_threshold, velocity_threshold

    radius = 6371000.0
    north = np.cumsum(speed * np.cos(psi)) * s.T
    east = np.cumsum(speed * np.sin(psi)) * s.T
    lat = 59.9 + np.degrees(north / radius)
    lon = 10.7 + np.degrees(east / (radius * np.cos(np.radians(lat))))
    truth.update({"latitude": lat / s.position_lsb, "longitude": lon / s.position_lsb})
    metre = np.degrees(1.0 / radius) / s.position_lsb
    noise.update({"latitude": s.position_noise * metre, "longitude": s.position_noise * metre / np.cos(np.radians(59.9))})
    thresholds = {"east velocity": velocity_threshold(s.a_max, s.T, s.velocity_lsb),
                  "north velocity": velocity_threshold(s.a_max, s.T, s.velocity_lsb),
                  "heading": attitude_threshold(s.omega_max, s.T, s.heading_lsb),
                  "latitude": position_threshold(s.v_max, s.T, s.position_lsb),
                  "longitude": position_threshold(s.v_max, s.T, s.position_lsb)}
    # the figures of a position in metres: a code of latitude is R * 1e-7 deg, of longitude that times cos(lat)
    lsb = {"heading": s.heading_lsb, "latitude": 1.0 / metre, "longitude": np.cos(np.radians(59.9)) / metre}
    extra = {"latitude": {"input_bits": 32},
             "longitude": {"input_bits": 32}}
    out = {}
    for name, clean in truth.items():
        measured = np.round(clean + rng.normal(0, noise[name], n)).astype(np.int64)
        unit = "m/s" if "velocity" in name else "deg" if name == "heading" else "m"
        out[name] = (clean, measured, thresholds[name], lsb.get(name, s.velocity_lsb), unit, extra.get(name, {}))
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
    for i, (name, (truth, measured, threshold, lsb, unit, extra)) in enumerate(signals.items()):
        params = th.Tukey53HParams(threshold=threshold, **extra)
        raw = th.inject_outliers(measured, seed * 16 + i, threshold, density=s.density, sizes=s.sizes, burst=s.burst,
                                 bits=params.input_bits)
        config = FilterConfig(filter="tukey53h", params=params)
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
            "comparators": _comparators(), "first_outlier": _first_outlier(s, signals["east velocity"], seed)}


def _limits(s, signal, seed):
    """What 53H removes by burst length, size and density (east velocity): removed %, false replacements."""
    from kfpga.core.config import FilterConfig
    from kfpga.core.fixedmodel import FixedModel
    from kfpga.model import tukey53h as th

    truth, measured, threshold, lsb, _, _ = signal
    model = FixedModel(FilterConfig(filter="tukey53h", params=th.Tukey53HParams(threshold=threshold)))
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
    return {"median of 5": m5, "median of 3": dict(ops.counts), "whole update": update_cost(FilterConfig(filter="tukey53h"),
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
    lines += ["", "RMSE against the noise-free signal in m/s, deg or m (all samples, and inliers only); removed: outliers "
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
              f"{c['whole update']['multiplications']} multiplications",
              "the paper's data (11 h of sea trials) is not available; the signals here are synthetic, with the "
              "outliers known, which the paper's figures cannot give."]
    return "\n".join(lines)


#: The signals of the paper's figs. 5-6 (velocity) and heading, and the positions of its sec. 3.
FIGURES = ("east velocity", "north velocity", "heading")
POSITIONS = ("latitude", "longitude")


def _first_outlier(s, signal, seed):
    """The east velocity with an outlier (10 thresholds) as its very first sample: what the online
    and the offline 53H (bit-accurate) give at sample 0, against the measured value."""
    from kfpga.core.config import FilterConfig
    from kfpga.core.fixedmodel import FixedModel
    from kfpga.model import tukey53h as th

    _, measured, threshold, _, _, _ = signal
    raw = measured.copy()
    raw[0] = np.clip(raw[0] + (10 if seed % 2 else -10) * threshold, -32768, 32767)
    model = FixedModel(FilterConfig(filter="tukey53h", params=th.Tukey53HParams(threshold=threshold)))
    online = model.run(raw).y
    offline = th.offline(raw, run=lambda x: model.run(x).y)
    return {"measured": int(measured[0]), "outlier": int(raw[0]), "online": int(online[th.DELAY]),
            "offline": int(offline[0]), "threshold": threshold,
            "online_false": int(np.sum(online[th.DELAY:] != raw[:len(raw) - th.DELAY]) - (online[th.DELAY] != raw[0]))}


def tukey53h_claims(options, result, runs):
    """The paper's claims (§1, §3), judged on every seed."""
    from kfpga.core.claims import Claim, spread

    methods = list(dict.fromkeys(r["method"] for r in result["rows"]))
    online = next(m for m in methods if m.startswith("53H online, bit"))
    offline = next(m for m in methods if m.startswith("53H offline"))
    cubic = next(m for m in methods if "cubic" in m)
    wls = next(m for m in methods if "weighted" in m)

    def per_run(method, key, pick, signals=FIGURES):
        return [pick(r[key] for r in run["rows"] if r["method"] == method and r["signal"] in signals) for run in runs]

    removed = {m: per_run(m, "removed_pct", min) for m in (online, offline, cubic, wls)}
    false = {m: per_run(m, "false_replacements", max) for m in (online, offline)}
    distorted = {m: per_run(m, "distorted", max) for m in (offline, cubic, wls)}
    signals = FIGURES

    def below_raw(run):
        rmse = {(r["signal"], r["method"]): r["rmse"] for r in run["rows"]}
        return all(rmse[(sig, cubic)] < rmse[(sig, "raw (no filter)")] for sig in signals)

    first = [run["first_outlier"] for run in runs]
    runs3 = [next(r for r in run["limits"] if r["case"] == "runs of 3")["removed_pct"] for run in runs]
    position = {key: per_run(offline, key, pick, POSITIONS) for key, pick in (("removed_pct", min),
                                                                              ("false_replacements", max))}
    by_signal = {sig: per_run(offline, "removed_pct", min, (sig,)) for sig in POSITIONS}
    return [
        Claim("the improved 53H removes every outlier (figs. 5-6; velocities and heading)", "all removed (curves)",
              [a == 100.0 and b == 100.0 for a, b in zip(removed[online], removed[offline], strict=True)],
              f"removed at worst over the three signals: online {spread(removed[online])} %, offline "
              f"{spread(removed[offline])} %", "single outliers and runs of 2 at 1 % of the samples; runs of 3 pass "
              f"the median of 5 ({spread(runs3, '.3g')} % of them removed)"),
        Claim("... and keeps the original data true: no inlier changed (figs. 5-6)", "no distortion (curves)",
              [a == 0 and b == 0 and c == 0 for a, b, c in zip(false[online], false[offline], distorted[offline], strict=True)],
              f"false replacements online {spread(false[online], '.3g')}, offline {spread(false[offline], '.3g')}; "
              f"inliers distorted {spread(distorted[offline], '.3g')}"),
        Claim("5-point cubic smoothing is severely distorted (figs. 5-6)", "distorted (curves)",
              [d > 0 for d in distorted[cubic]], f"inliers left beyond the threshold: {spread(distorted[cubic], '.4g')}"),
        Claim("5-point cubic smoothing does not remove large outliers, only weakens them (figs. 5-6)", "curves",
              [r < 100.0 and below_raw(run) for r, run in zip(removed[cubic], runs, strict=True)],
              f"removed {spread(removed[cubic], '.3g')} %; its RMSE below the raw data's on every signal"),
        Claim("the sliding least-squares filter does not distort (figs. 5-6)", "no distortion (curves)",
              [d == 0 for d in distorted[wls]], f"inliers left beyond the threshold: {spread(distorted[wls], '.4g')}",
              "it spreads every large outlier over its window"),
        Claim("the sliding least-squares filter does not remove every outlier (figs. 5-6)", "curves",
              [r < 100.0 for r in removed[wls]], f"removed {spread(removed[wls], '.3g')} %"),
        Claim("the 53H online smoother delays its output by 4 samples (sec. 1)", "4 samples",
              [r["delay"] == 4 for r in result["rows"] if r["method"] == online][:1],
              "4 samples (the median of 5, then of 3, then the Hanning weights)", "the structure, the same on every seed"),
        Claim("the improved 53H also smooths the first and the last 4 samples (sec. 1, steps 5-6)",
              "the ends smoothed by the reversed series",
              [abs(f["offline"] - f["measured"]) <= f["threshold"] for f in first],
              "an outlier as the very first sample: offline brings it within the threshold of the measured value on "
              f"{sum(abs(f['offline'] - f['measured']) <= f['threshold'] for f in first)} of {len(first)} seeds; "
              "online (which has no "
              "reversed series) passes it, then replaces good samples on "
              f"{sum(f['online_false'] > 0 for f in first)} of them",
              "held when the offline form restores it. The online core cannot: the paper's reversal of the first 8 "
              "samples needs 8 samples before the first output, and the core keeps its fixed 4-sample delay"),
        Claim("latitude and longitude: the threshold V_max T / R finds their outliers (sec. 3)", "Tp = V_max / R",
              [r == 100.0 and f == 0 for r, f in zip(position["removed_pct"], position["false_replacements"],
                                                      strict=True)],
              "offline, 32-bit samples of 1e-7 deg, V_max = 12 m/s: removed " + ", ".join(
                  f"{sig} {spread(v, '.3g')} %" for sig, v in by_signal.items())
              + f"; false replacements {spread(position['false_replacements'], '.3g')}",
              "at 59.9 deg N a longitude moves 1/cos(lat) = 2x faster than a latitude: at 9 m/s east the ship moves "
              "further in one second than the threshold, and the median's value near an outlier is off by that "
              "step; position_threshold() / cos(lat) is the longitude's"),
        Claim("the method needs neither normally distributed data nor their standard deviation (introduction)",
              "a property of the median", None, "the thresholds here come from a_max T and omega_max T only",
              "a property of the algorithm, not a figure: no run can fail it"),
    ]


def tukey53h_plot(result, path):
    """The paper's figs. 5-6: east and north velocity before and after each method."""
    from kfpga.model.plots import pyplot, save_figure

    plt = pyplot()

    names = ["east velocity", "north velocity"]
    fig, axes = plt.subplots(len(names), 1, figsize=(13, 8), sharex=True)
    for ax, name in zip(axes, names, strict=True):
        s = result["series"][name]
        t = np.arange(len(s["raw"]))
        ax.plot(t, s["raw"], color="0.75", lw=0.6, label="measured (with outliers)")
        # the clean signal wide and pale underneath, so that a method on it stays visible
        ax.plot(t, s["clean"], color="#f4a6a6", lw=3.0, label="clean (noise-free)")
        for method, colour in ((next(m for m in s if "cubic" in m), "C1"), (next(m for m in s if "weighted" in m), "C2"),
                               (next(m for m in s if m.startswith("53H offline")), "C0")):
            ax.plot(t, s[method], lw=0.8, color=colour, label=method)
        lo, hi = float(np.min(s["clean"])), float(np.max(s["clean"]))
        ax.set_ylim(lo - 0.3 * (hi - lo) - 0.5, hi + 0.3 * (hi - lo) + 0.5)
        ax.set(title=f"{name}: outliers clipped by the axes", ylabel=f"{name} ({s['unit']})")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=5, fontsize=8)
    axes[-1].set_xlabel(f"time (s), seed {result['seed']}")
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    save_figure(fig, path, dpi=110)




def _add_arguments(parser):
    parser.add_argument("--a-max", type=float, metavar="M_S2", help="the ship's largest acceleration, m/s^2: the "
                                                                  "velocities' threshold a_max T (default: 0.5)")
    parser.add_argument("--omega-max", type=float, metavar="DEG_S", help="its largest turn rate, deg/s: the heading's "
                                                                       "threshold omega_max T (default: 3)")
    parser.add_argument("--v-max", type=float, metavar="M_S", help="its largest speed, m/s: latitude's and "
                                                                 "longitude's threshold V_max T / R (default: 12)")
    parser.add_argument("--density", type=float, metavar="P", help="share of the samples that start a run of "
                                                                 "outliers, 0..0.2 (default: 0.01)")


def _scenario(options):
    from kfpga.core.errors import UsageError

    given = {k: getattr(options, k) for k in ("a_max", "omega_max", "v_max", "density") if getattr(options, k) is not None}
    for key, top in (("a_max", 100.0), ("omega_max", 90.0), ("v_max", 100.0), ("density", 0.2)):
        if key in given and not 0.0 < given[key] <= top:
            raise UsageError(f"--{key.replace('_', '-')} must be in (0, {top:g}], not {given[key]:g}")
    return NavigationScenario(**given)


EVALUATION = Evaluation(
    summary="[Lu]: the 53H outlier smoother on a ship's navigation data against 5-point cubic smoothing and "
            "sliding weighted least squares",
    description="A ship's INS east and north velocity, heading, latitude and longitude at 1 Hz for an hour "
                "(synthetic: turns, a speed change, sea-induced yaw and surge, sensor noise; positions in 32-bit "
                "samples of 1e-7 deg), with seeded outliers of several sizes, single and in runs of 2, smoothed by "
                "the online and the offline 53H (bit-accurate; thresholds a_max*T, omega_max*T and V_max*T/R), the "
                "5-point cubic smoothing and a sliding weighted least-squares filter. Prints, per signal and method, "
                "the outliers removed, false replacements, distorted inliers, RMSE and delay; what 53H cannot remove "
                "(runs of 3 and more, dense outliers); and the paper's claims over the seeds.",
    add_arguments=_add_arguments,
    check=lambda options: _scenario(options),
    run=lambda options, seed: tukey53h(_scenario(options), seed=seed),
    table=tukey53h_table,
    summary_json=lambda r: {k: r[k] for k in ("seed", "scenario", "rows", "limits", "comparators", "first_outlier")},
    claims=tukey53h_claims,
    plot=tukey53h_plot,
)
