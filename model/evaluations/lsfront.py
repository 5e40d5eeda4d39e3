"""The least-squares front end's source document, rerun: ``kfpga evaluate lsfront`` ([Fukuda]).

The patent's fig. 4: a ship decelerating from constant speed to a stop, its speed log noisy;
the Kalman filter fed by the least-squares line, the one observing velocity and a measured
acceleration, the velocity-only filter and the moving average; noise suppression and
responsiveness, and the bit-accurate front end against its float form.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kfpga.core.spec import Evaluation


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


def _figures(name, est, truth, t, s):
    """One curve's noise suppression and responsiveness (see :class:`DecelerationScenario`)."""
    cruise = (t >= 50) & (t < s.t0)
    ramp = (t >= s.t0 + 20) & (t < s.t_stop - 10)
    stopped = t >= s.t_stop + 100
    e = est - truth
    mean_e = np.convolve(e, np.ones(s.average) / s.average, mode="same")
    below = np.flatnonzero((t >= s.t0) & (est <= s.v0 - s.drop))
    onset = float(t[below[0]] - (s.t0 + s.drop / s.decel)) if below.size else None
    after = (t >= s.t_stop) & (t < s.t_stop + 100)
    return {"filter": name, "rmse_cruise": float(np.sqrt(np.mean(e[cruise] ** 2))),
            "rmse_stopped": float(np.sqrt(np.mean(e[stopped] ** 2))),
            "rmse_ramp": float(np.sqrt(np.mean(e[ramp] ** 2))), "onset_delay_s": onset,
            "lag_s": float(np.mean(e[ramp]) / s.decel), "undershoot": float(max(0.0, -np.min(mean_e[after])))}


def equal_suppression_q(v, truth, t, s, params, target):
    """The q of the velocity-only filter whose RMSE at constant speed equals ``target`` (the
    LS-fed filter's), by bisection on log q: the baseline at the same noise suppression."""
    from dataclasses import replace

    from kfpga.model import lsfront as ls

    def cruise(q):
        return _figures("", ls.kalman_va(v, replace(params, q=q))["velocity"], truth, t, s)["rmse_cruise"]

    lo, hi = -14.0, -1.0  # log10 q: the RMSE rises with q
    for _ in range(30):
        mid = (lo + hi) / 2.0
        lo, hi = (mid, hi) if cruise(10.0 ** mid) < target else (lo, mid)
    return 10.0 ** ((lo + hi) / 2.0)


def lsfront(scenario=None, *, seed, params=None):
    """The patent's four curves on the deceleration scenario, and the velocity-only filter at the
    LS-fed one's noise suppression: ``{seed, scenario, params, rows, series, ...}``."""
    from dataclasses import replace

    from kfpga.model import lsfront as ls

    s = DecelerationScenario() if scenario is None else scenario
    params = ls.LSFrontParams(T=s.T, r=s.sigma_v ** 2) if params is None else params
    t, truth, v, a = deceleration_log(s, seed)
    fed = ls.lsfront(v, params)
    fixed = lsfront_fixed(v, params)
    fed_cruise = _figures("", fed["velocity"], truth, t, s)["rmse_cruise"]
    q_equal = equal_suppression_q(v, truth, t, s, params, fed_cruise)
    both = ls.kalman_va(v, params, a=a, r_a=s.sigma_a ** 2)["velocity"]
    curves = {
        FED: fed["velocity"],
        BOTH: both,
        VONLY: ls.kalman_va(v, params)["velocity"],
        VONLY_EQUAL: ls.kalman_va(v, replace(params, q=q_equal))["velocity"],
        f"moving average ({s.window} samples)": ls.moving_average(v, s.window),
        SWITCHED: fixed.pop("float"),
        BIT_ACCURATE: fixed.pop("fixed"),
    }
    rows = [{**_figures("speed log (raw)", v, truth, t, s), "onset_delay_s": None, "lag_s": None, "undershoot": None}]
    rows += [_figures(name, est, truth, t, s) | {"from_both": float(np.sqrt(np.mean((est - both)[t >= s.t0 - 50] ** 2)))}
             for name, est in curves.items()]
    windows = np.bincount(fed["Ns"], minlength=max(params.windows) + 1)
    return {"seed": seed, "scenario": {k: getattr(s, k) for k in s.__dataclass_fields__},
            "params": {"T": params.T, "q": params.q, "r": params.r, "table": [list(r) for r in params.table],
                       "q_equal_suppression": q_equal},
            "rows": rows, "windows": {int(n): int(c) for n, c in enumerate(windows) if c},
            "mean_window": float(np.mean(fed["Ns"])), "fixed": fixed,
            "series": {"t": t, "truth": truth, "raw": v, **curves, "Ns": fed["Ns"]}}


FED = "LS-fed Kalman (the patent, x0)"
BOTH = "Kalman, velocity and acceleration observed (x1)"
VONLY = "Kalman, velocity only (x2)"
VONLY_EQUAL = "Kalman, velocity only, equal suppression"
#: The rows of the front end's fixed-point form: in float, and in the core's integers.
SWITCHED = "LS-fed, a steady-state gain per mode (float)"
BIT_ACCURATE = "LS-fed, bit-accurate (the core's integers)"


def lsfront_fixed(v, params):
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


def lsfront_table(result):
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
              f"velocity only, equal suppression: q = {result['params']['q_equal_suppression']:.3g} (the patent's filter's "
              f"q = {result['params']['q']:g}), chosen so that its RMSE at constant speed equals the LS-fed filter's.",
              "", lsfront_fixed_text(result["fixed"]), "",
              "the patent gives curves, not figures; the scenario's numbers (speed, rate, noise) are this code's own."]
    return "\n".join(lines)


def lsfront_fixed_text(fixed):
    gains = "; ".join(f"{mode}: K = {k}".replace("], [", "; ") for mode, k in
                      ((m, [[round(g, 4) for g in row] for row in k]) for m, k in fixed["gains"].items()))
    return (f"fixed point (the core's integers; formats {', '.join(f'{k} {v}' for k, v in fixed['formats'].items())}): "
            f"the running sums exact, the slope one product by 2^s/D per window, the line's end value S0/n + slope "
            f"(n-1)/2; at most {fixed['max_from_float']:.5f} m/s from the same filter in float "
            f"({fixed['rms_from_float']:.5f} rms), the acceleration at most {fixed['accel_max_from_float']:.6f} m/s^2; "
            f"{fixed['overflows']} overflows, the window different from float's in {fixed['window_differs']} of "
            f"{fixed['samples']} samples. Its steady-state gains (velocity, acceleration per sample) per mode: {gains}.")


def lsfront_claims(options, result, runs):
    """The patent's claims, judged on every seed (and, for the window, over three noise levels)."""
    from kfpga.core.claims import Claim, spread

    def fig(name, key):
        return [next(r for r in run["rows"] if r["filter"].startswith(name))[key] for run in runs]

    mean = "moving average"
    fed = {k: fig(FED, k) for k in ("rmse_cruise", "rmse_stopped", "onset_delay_s", "lag_s", "undershoot", "from_both")}
    vo = {k: fig(VONLY, k) for k in ("rmse_cruise", "onset_delay_s", "lag_s", "undershoot", "from_both")}
    eq = {k: fig(VONLY_EQUAL, k) for k in ("rmse_cruise", "onset_delay_s", "lag_s", "undershoot")}
    ma = {k: fig(mean, k) for k in ("rmse_cruise", "lag_s")}

    def quicker(other):
        return [f_on <= o_on and abs(f_lag) <= abs(o_lag) and f_un <= o_un for f_on, o_on, f_lag, o_lag, f_un, o_un in
                zip(fed["onset_delay_s"], other["onset_delay_s"], fed["lag_s"], other["lag_s"], fed["undershoot"],
                    other["undershoot"], strict=True)]

    def resp(d):
        return (f"onset {spread(d['onset_delay_s'], '.3g')} s, lag {spread(d['lag_s'], '.3g')} s, undershoot "
                f"{spread(d['undershoot'], '.3g')} m/s")

    noise = [run.get("window_by_noise") for run in runs]
    return [
        Claim("high noise suppression: the LS-fed filter (x0) is quieter at constant speed than the velocity-only "
              "Kalman filter (x2) and the moving average ([0362], [0402])", "curves (fig. 4), no figure",
              [f < v and f < m for f, v, m in zip(fed["rmse_cruise"], vo["rmse_cruise"], ma["rmse_cruise"], strict=True)],
              f"RMSE at constant speed {spread(fed['rmse_cruise'])} m/s against {spread(vo['rmse_cruise'])} (x2) and "
              f"{spread(ma['rmse_cruise'])} (moving average)"),
        Claim("x0 responds better than x2, the velocity-only filter (fig. 4, [0373])", "curves (fig. 4)",
              quicker(vo), f"x0: {resp(fed)}; x2: {resp(vo)}",
              "held when x0 is no later at the onset, lags no more in the ramp and undershoots no more after the stop"),
        Claim("... also against x2 at the same noise suppression (its q raised until its RMSE at constant speed "
              "equals x0's)", "not in the patent: the fair form of the same comparison", quicker(eq),
              f"x2 at equal suppression: {resp(eq)}"),
        Claim("x0 approximates x1, the filter that observes velocity and acceleration (fig. 4, [0373])", "curves",
              [f < v for f, v in zip(fed["from_both"], vo["from_both"], strict=True)],
              f"RMS distance from x1 from the deceleration on: x0 {spread(fed['from_both'])} m/s, x2 "
              f"{spread(vo['from_both'])} m/s", "held when x0 is closer to x1 than x2 is"),
        Claim("the moving average with a similar noise suppression responds worse (x3, [0143])", "curves",
              [abs(f) < abs(m) for f, m in zip(fed["lag_s"], ma["lag_s"], strict=True)],
              f"lag in the ramp: x0 {spread(fed['lag_s'], '.3g')} s, moving average {spread(ma['lag_s'], '.3g')} s"),
        Claim("when the observation noise is large, Ns is large ([0394])", "said, no figure",
              [n[-1][1] > n[0][1] for n in noise],
              "mean window Ns at speed-log noise " + ", ".join(
                  f"{sigma:g} m/s: {spread([n[i][1] for n in noise], '.3g')}" for i, (sigma, _) in enumerate(noise[0])),
              "the same table of thresholds at every noise: a larger innovation picks a shorter window"),
    ]


def _window_by_noise(options, seed):
    """The LS-fed filter's mean window at three speed-log noises (r following the noise)."""
    from dataclasses import replace

    from kfpga.model import lsfront as ls

    base = _scenario(options)
    out = []
    for sigma in (base.sigma_v / 2.0, base.sigma_v, base.sigma_v * 2.0):
        s = replace(base, sigma_v=sigma)
        _, _, v, _ = deceleration_log(s, seed)
        params = replace(_params(options, base), r=sigma ** 2)
        out.append((sigma, float(np.mean(ls.lsfront(v, params)["Ns"]))))
    return out


def lsfront_plot(result, path):
    """The patent's fig. 4: the velocity estimates through the deceleration, and their errors."""
    from kfpga.model.plots import pyplot, save_figure

    plt = pyplot()

    s = result["series"]
    t = s["t"]
    names = [r["filter"] for r in result["rows"][1:] if r["filter"] != VONLY_EQUAL]
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
    save_figure(fig, path, dpi=110)


def _add_arguments(parser):
    parser.add_argument("--q", type=float, metavar="Q", help="the filter's process noise on the acceleration per step "
                                                            "(default: 1e-5)")
    parser.add_argument("--noise", type=float, metavar="M_S", help="the speed log's noise, m/s (default: 0.1); the "
                                                                 "filter's r follows it (noise^2)")
    parser.add_argument("--table", metavar="T:NS,...", help="the window table: an innovation below each threshold "
                                                            "(m/s) picks Ns, the last threshold inf (default: "
                                                            "0.1:30,0.3:12,inf:5)")


def _scenario(options):
    from kfpga.core.errors import UsageError

    if options.noise is not None and not 0.0 < options.noise <= 10.0:
        raise UsageError(f"--noise must be in (0, 10] m/s, not {options.noise:g}")
    return DecelerationScenario() if options.noise is None else DecelerationScenario(sigma_v=options.noise)


def _params(options, scenario):
    from kfpga.core.errors import UsageError
    from kfpga.model import lsfront as ls

    kwargs = {"T": scenario.T, "r": scenario.sigma_v ** 2}
    if options.q is not None:
        kwargs["q"] = options.q
    if options.table is not None:
        try:
            kwargs["table"] = tuple((float(t), int(n)) for t, n in (row.split(":") for row in options.table.split(",")))
        except ValueError:
            raise UsageError(f"--table must be threshold:Ns pairs separated by commas (0.1:30,0.3:12,inf:5), not "
                             f"{options.table!r}") from None
    try:
        return ls.LSFrontParams(**kwargs)
    except (TypeError, ValueError) as exc:
        raise UsageError(f"--{'table' if 'table' in str(exc) or 'Ns' in str(exc) or 'threshold' in str(exc) else 'q'}: "
                         f"{exc}") from None


def _run(options, seed):
    scenario = _scenario(options)
    return lsfront(scenario, seed=seed, params=_params(options, scenario)) | {
        "window_by_noise": _window_by_noise(options, seed)}


EVALUATION = Evaluation(
    summary="[Fukuda]: the least-squares pseudo-acceleration front end of a Kalman filter, on a ship decelerating "
            "to a stop",
    description="A ship at constant speed decelerating at a constant rate to a stop, its speed log noisy (the "
                "patent's fig. 4). The patent's four curves: the Kalman filter fed with the least-squares line's "
                "velocity and slope (window Ns from the innovation), the Kalman filter observing velocity and a "
                "measured acceleration, the velocity-only Kalman filter and the moving average. Prints noise "
                "suppression (RMSE at constant speed and stopped) and responsiveness (onset delay, lag in the ramp, "
                "undershoot after the stop), and how they compare with the patent.",
    add_arguments=_add_arguments,
    check=lambda options: _params(options, _scenario(options)),
    run=_run,
    table=lsfront_table,
    summary_json=lambda r: {k: r[k] for k in ("seed", "scenario", "params", "rows", "windows", "mean_window", "fixed",
                                              "window_by_noise")},
    claims=lsfront_claims,
    plot=lsfront_plot,
)
