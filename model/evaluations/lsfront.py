"""The least-squares front end's source document, rerun: ``kfpga evaluate lsfront`` (seeds/003).

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
    from kfpga.core.plots import pyplot, save_figure

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
    save_figure(fig, path, dpi=110)


EVALUATION = Evaluation(
    summary="seeds/003: the least-squares pseudo-acceleration front end of a Kalman filter, on a ship decelerating "
            "to a stop",
    description="A ship at constant speed decelerating at a constant rate to a stop, its speed log noisy (the "
                "patent's fig. 4). The patent's four curves: the Kalman filter fed with the least-squares line's "
                "velocity and slope (window Ns from the innovation), the Kalman filter observing velocity and a "
                "measured acceleration, the velocity-only Kalman filter and the moving average. Prints noise "
                "suppression (RMSE at constant speed and stopped) and responsiveness (onset delay, lag in the ramp, "
                "undershoot after the stop), and how they compare with the patent.",
    add_arguments=lambda parser: None,
    run=lambda options, seed: ls_frontend(seed=seed),
    table=ls_frontend_table,
    summary_json=lambda r: ({k: r[k] for k in ("seed", "scenario", "params", "rows", "windows", "fixed")}
                            | {"findings": ls_frontend_findings(r)}),
    plot=ls_frontend_plot,
)
