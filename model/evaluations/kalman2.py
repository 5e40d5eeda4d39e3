"""The paper's own evaluation, rerun: ``kfpga evaluate kalman2`` ([Zhong]).

Its Simulink test: a sine with white Gaussian noise through the 2-state filter; the time-varying
filter and its steady-state form (the gain K_inf in place of K_k); the covariance from any P0 to
its steady value; and fixed point (the cores' integers) against float on the same ADC codes.
"""

from __future__ import annotations

import numpy as np

from kfpga.core.spec import Evaluation

#: Samples of a run, and the start-up both filters are given before errors are counted.
SAMPLES, SETTLE = 4000, 200


def _p_after(params, p0, steps):
    """The time-varying filter's covariance after ``steps`` updates from ``p0`` (the paper's
    equations, in float64)."""
    phi = np.array([[1.0, params.T], [0.0, 1.0]])
    gq = np.array([[0.0, 0.0], [0.0, params.Q * params.T ** 2]])  # the paper's G Q G^T, per sample
    c = np.array([[1.0, 0.0]])
    p = np.array(p0, dtype=np.float64)
    for _ in range(steps):
        pl = phi @ p @ phi.T + gq
        k = pl @ c.T / (c @ pl @ c.T + params.R)
        p = (np.eye(2) - k @ c) @ pl
    return p


def kalman2(*, seed, params=None, samples=SAMPLES):
    """One run: ``{seed, params, rows, steady_gap, covariance}``."""
    from kfpga.core.config import FilterConfig
    from kfpga.core.fixedmodel import FixedModel
    from kfpga.model import kalman2 as k2
    from kfpga.model.reference import KalmanParams
    from kfpga.model.scenarios import for_config

    params = KalmanParams() if params is None else params
    config = FilterConfig(filter="kalman2", params=params)
    truth, codes = for_config("sine", samples, seed, config)
    rows = [{"filter": "noisy input", "rmse": float(np.sqrt(np.mean((codes - truth)[SETTLE:] ** 2))),
             "max_error": float(np.max(np.abs(codes - truth)[SETTLE:]))}]
    outs = {}
    for variant in ("full", "steady"):
        flt = k2.reference(params, variant, codes.astype(np.float64))["x1"]
        model = FixedModel(config, variant=variant)
        fixed = model.to_float(model.run(codes))["x1"]
        outs[variant] = flt
        for form, est in (("float", flt), ("fixed", fixed)):
            e = (est - truth)[SETTLE:]
            rows.append({"filter": f"{'time-varying' if variant == 'full' else 'steady-state'} ({form})",
                         "rmse": float(np.sqrt(np.mean(e ** 2))), "max_error": float(np.max(np.abs(e)))})
        d = (fixed - flt)[SETTLE:]
        rows[-1]["from_float_max"] = float(np.max(np.abs(d)))
    gap = np.abs(outs["steady"] - outs["full"])
    rng = np.random.default_rng([seed, 1])
    starts = [np.diag([10.0, 10.0]), np.diag([1e4, 1e4]), np.diag([1e-3, 1e-3])]
    a = rng.normal(size=(2, 2))
    starts.append(a @ a.T * 100.0 + np.eye(2))
    settled = [_p_after(params, p0, 500) for p0 in starts]
    spread = max(float(np.max(np.abs(p - settled[0]))) for p in settled)
    return {"seed": seed, "params": {"T": params.T, "Q": params.Q, "R": params.R}, "rows": rows,
            "amplitude": float(np.max(np.abs(truth))),
            "steady_gap": {"first_20": float(np.max(gap[:20])), "last_half": float(np.max(gap[len(gap) // 2:]))},
            "covariance": {"starts": len(starts), "spread_after_500": spread,
                           "p11": float(settled[0][0, 0])}}


def kalman2_table(result):
    lines = [f"seed {result['seed']}: the paper's sine (amplitude {result['amplitude']:g} codes) with white noise of "
             f"variance R = {result['params']['R']:g}, T = {result['params']['T']:g}, Q = {result['params']['Q']:g}; "
             f"{SAMPLES} samples, errors from sample {SETTLE} on (codes)", "",
             f"{'filter':<28} {'RMSE':>8} {'max |error|':>12} {'max |fixed - float|':>20}"]
    for r in result["rows"]:
        extra = f"{r['from_float_max']:>20.4f}" if "from_float_max" in r else ""
        lines.append(f"{r['filter']:<28} {r['rmse']:>8.4f} {r['max_error']:>12.4f} {extra}")
    g, c = result["steady_gap"], result["covariance"]
    lines += ["", f"steady-state gain in place of K_k (float): at most {g['first_20']:.3f} codes apart over the first 20 "
              f"samples, {g['last_half']:.2e} over the second half",
              f"covariance from {c['starts']} different P0 (10 I, 1e4 I, 1e-3 I, a random one): after 500 updates at "
              f"most {c['spread_after_500']:.2e} apart (p11 = {c['p11']:.4f})"]
    return "\n".join(lines)


def kalman2_claims(options, result, runs):
    from kfpga.core.claims import Claim, spread

    def row(run, name):
        return next(r for r in run["rows"] if r["filter"] == name)

    raw = [row(run, "noisy input")["rmse"] for run in runs]
    full = [row(run, "time-varying (fixed)")["rmse"] for run in runs]
    steady = [row(run, "steady-state (fixed)")["rmse"] for run in runs]
    worst = [row(run, "time-varying (fixed)")["max_error"] for run in runs]
    first = [run["steady_gap"]["first_20"] for run in runs]
    last = [run["steady_gap"]["last_half"] for run in runs]
    fixed_gap = [max(row(run, n)["from_float_max"] for n in ("time-varying (fixed)", "steady-state (fixed)"))
                 for run in runs]
    amplitude = result["amplitude"]
    return [
        Claim("the filtered noisy sine matches the sine without noise (figs. 11-13)", "curves",
              [f < r for f, r in zip(full, raw, strict=True)],
              f"RMSE against the clean sine: filtered (the core's integers) {spread(full)} codes, the noisy input "
              f"{spread(raw)} codes", "held when the filter's error is below the noise it was given"),
        Claim("once settled, the error stays within 0.5 deg (fig. 13)", "0.5 deg", None,
              f"largest error after sample {SETTLE}: {spread(worst)} codes on a sine of {amplitude:g} codes "
              f"({spread([100 * w / amplitude for w in worst], '.3g')} % of it)",
              "the paper gives neither the sine's amplitude nor its noise in degrees: no scale to hold 0.5 deg to"),
        Claim("the steady-state gain K_inf in place of K_k errs only in the first steps, then ever less (sec. 4.3)",
              "said, no figure", [a > 100 * b for a, b in zip(first, last, strict=True)],
              f"steady against time-varying (float): {spread(first)} codes apart in the first 20 samples, "
              f"{spread(last, '.2e')} over the second half", "held when the late gap is below 1 % of the early one"),
        Claim("from any initial P0, P_k goes to its steady value (sec. 4.3)", "said, no figure",
              [run["covariance"]["spread_after_500"] < 1e-6 for run in runs],
              f"four P0 from 1e-3 I to 1e4 I: {spread([run['covariance']['spread_after_500'] for run in runs], '.2e')} "
              "apart after 500 updates"),
        Claim("the generated hardware gives the model's results (ModelSim agrees with Simulink, fig. 14)",
              "waveforms alike", None, f"the cores' integers at most {spread(fixed_gap, '.3g')} codes from float",
              "the hardware is not run here: kfpga simulate and the test suite hold the RTL to these integers, "
              "bit-exact on Verilator and Icarus"),
        Claim("the steady-state filter is as accurate as the time-varying one after the start (sec. 4.3)",
              "said, no figure", [abs(s / f - 1) < 0.01 for s, f in zip(steady, full, strict=True)],
              f"RMSE steady {spread(steady)} codes, time-varying {spread(full)} codes",
              "held when the two are within 1 %"),
    ]


def _add_arguments(parser):
    parser.add_argument("--samples", type=int, metavar="N", help=f"samples of a run (default: {SAMPLES}; at least "
                                                                 f"{2 * SETTLE})")


def _check(options):
    from kfpga.core.errors import UsageError

    if options.samples is not None and options.samples < 2 * SETTLE:
        raise UsageError(f"--samples must be at least {2 * SETTLE}, not {options.samples}")


EVALUATION = Evaluation(
    summary="[Zhong]: the paper's 2-state filter on its noisy sine, time-varying and steady-state, fixed and float",
    description="The paper's Simulink test: a sine with white Gaussian noise of variance R through the time-varying "
                "filter and its steady-state form, in float and in the cores' integers (default formats); how far "
                "the steady gain errs at the start; the covariance from four different P0. Prints the errors and the "
                "paper's claims over the seeds.",
    add_arguments=_add_arguments,
    check=_check,
    run=lambda options, seed: kalman2(seed=seed, samples=options.samples or SAMPLES),
    table=kalman2_table,
    summary_json=lambda r: {k: r[k] for k in ("seed", "params", "rows", "amplitude", "steady_gap", "covariance")},
    claims=kalman2_claims,
)
