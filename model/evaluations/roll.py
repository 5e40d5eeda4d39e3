"""The ship-roll predictor's source document, rerun: ``kfpga evaluate roll`` ([Zhang]).

The basic and the improved interval predictor on the paper's table 1 and a synthetic roll
series: prediction RMSE, a sweep over the fading factor, the bit-accurate predictor and a
word-length sweep of both covariance forms.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

from kfpga.core.errors import InputError, UsageError
from kfpga.core.spec import Evaluation

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


#: The sweeps of the paper's two claims on its noises (sec. 3): Q = q I and R.
Q_SWEEP = (0.25, 1.0, 4.0, 10.0)
R_SWEEP = (0.0025, 0.01, 0.04, 0.16)
#: The synthetic series' measurement noise (deg) by default; the paper's sensor is good to 0.1 deg.
NOISE = 0.02


def _same_predictions(z, pred, ref):
    """``prediction_rmse`` of two predictors over the predictions both made (each filter's start
    skipped by both)."""
    from kfpga.model import roll as rp

    both = np.isfinite(pred) & np.isfinite(ref)
    return rp.prediction_rmse(z, np.where(both, pred, np.nan)), rp.prediction_rmse(z, np.where(both, ref, np.nan))


def _fixed_row(data, z, params, form_opts):
    """The bit-accurate square-root predictor (default formats, each filter started from its
    first three samples as the paper does) against the float improved form on the same samples
    (the ADC codes) and the same predictions."""
    from dataclasses import replace

    from kfpga.core.config import FilterConfig
    from kfpga.model import roll as rp

    config = FilterConfig(filter="roll", params=replace(params, init="measurement"))
    pred, overflowed, not_pd = rp.predict_fixed(z, config, check=True)
    # the core's output n is the prediction of sample n + 2 from the start of the filter that took n;
    # during a filter's start (its first three samples) it is no prediction: those are left out
    from kfpga.model.scenarios import adc_codes

    ref = rp.predict(adc_codes(z / params.lsb) * params.lsb, params, **form_opts)  # the same samples: the ADC's codes
    pred = np.where(np.isfinite(ref), pred, np.nan)
    (fixed_err, count), (float_err, _) = _same_predictions(z, pred, ref)
    diff = (pred - ref)[:-2]
    diff = diff[np.isfinite(diff)]
    return {"data": data, "rmse_fixed_deg": fixed_err, "rmse_float_deg": float_err, "predictions": count,
            "max_from_float_deg": float(np.max(np.abs(diff))), "rms_from_float_deg": float(np.sqrt(np.mean(diff ** 2))),
            "overflowed": overflowed, "not_positive_definite": not_pd, "updates": len(z)}, pred


def roll(*, seed, samples=480, series=None, params=None, noise=NOISE, printed_a=False, sweep_words=True):
    """The roll evaluation: prediction RMSE of each form on the paper's table 1 and on a
    synthetic series (or ``series``: a user's ``(name, roll array)``), the sweeps over s, Q and R,
    the bit-accurate predictor against float on the same predictions, and the series the plot
    draws. ``printed_a``: every float form with eq. (22)'s A as printed."""
    from dataclasses import replace

    from kfpga.model import roll as rp

    params = rp.RollParams() if params is None else params
    sets = {}
    _, table = rp.table1()
    sets[TABLE1] = table
    if series is not None:
        sets[series[0]] = np.asarray(series[1], dtype=np.float64)
    else:
        _, y, _ = rp.synthetic_roll(samples, seed, T=params.T, noise=noise)
        sets[f"synthetic ({samples} samples, seed {seed})"] = y
    rows, sweep, plot, fixed, claims_sweeps = [], [], {}, [], []
    for data, z in sets.items():
        for name, opts in _ROLL_FORMS:
            p = rp.predict(z, params, printed_a=printed_a, **opts)
            err, count = rp.prediction_rmse(z, p)
            rows.append({"data": data, "form": name, "rmse_deg": err, "predictions": count})
            plot.setdefault(data, {"roll": z})[name] = p
        for s in ROLL_FADING:
            p = rp.predict(z, replace(params, s=s), printed_a=printed_a)
            sweep.append({"data": data, "s": s, "rmse_deg": rp.prediction_rmse(z, p)[0]})
        for key, values in (("q", Q_SWEEP), ("R", R_SWEEP)):
            for value in values:
                p = rp.predict(z, replace(params, **{key: value}), printed_a=printed_a)
                claims_sweeps.append({"data": data, "parameter": key, "value": value,
                                      "rmse_deg": rp.prediction_rmse(z, p)[0]})
        row, pred = _fixed_row(data, z, params, dict(_ROLL_FORMS[3][1]))
        fixed.append(row)
        plot[data]["bit-accurate (square root, default formats)"] = pred
    longest = max(sets, key=lambda d: len(sets[d]))
    words = rp.word_sweep(sets[longest], params) if sweep_words else []
    return {"seed": seed, "params": {"T": params.T, "q": params.q, "R": params.R, "s": params.s,
                                     "P0": [list(r) for r in params.P0], "lsb": params.lsb, "noise_deg": noise,
                                     "A": "as printed (bottom-right T)" if printed_a else "bottom-right 1"},
            "rows": rows, "sweep": sweep, "noise_sweeps": claims_sweeps, "series": plot,
            "formats": _formats(params),
            "fixed": fixed, "words": words, "words_data": longest}


TABLE1 = "table 1 (32 samples)"


def _formats(params):
    from kfpga.core.config import FilterConfig

    config = FilterConfig(filter="roll", params=params)
    return {k: str(v) for k, v in config.formats.items() if k in _ROLL_SQRT_POINTS}


def _p0_text(p0):
    flat = [v for row in p0 for v in row]
    if len(set(flat)) == 1:
        return f"all {flat[0]:g}s (the paper's: singular, so the square root starts from A P0 A' + Q)" if flat[0] == 10 \
            else f"all {flat[0]:g}s"
    return "[" + "; ".join(", ".join(f"{v:g}" for v in row) for row in p0) + "]"


def roll_table(result):
    w = max(34, *(len(r["data"]) for r in result["rows"]))
    lines = [f"T = {result['params']['T']:g} s, two filters on alternate samples, each predicting 2 samples "
             f"(1 s) ahead; Q = {result['params']['q']:g} I, R = {result['params']['R']:g}, s = {result['params']['s']:g}, "
             f"P0 {_p0_text(result['params']['P0'])}, A {result['params']['A']}; RMSE of the prediction "
             "against the sample it predicts", "",
             f"{'data':<{w}} {'form':<40} {'RMSE (deg)':>10} {'predictions':>12}"]
    for r in result["rows"]:
        lines.append(f"{r['data']:<{w}} {r['form']:<40} {r['rmse_deg']:>10.4f} {r['predictions']:>12}")
    lines += ["", "fading factor s (improved form):", f"{'data':<{w}} " + "".join(f"{s:>8g}" for s in ROLL_FADING)]
    for data in dict.fromkeys(r["data"] for r in result["sweep"]):
        lines.append(f"{data:<{w}} " + "".join(f"{r['rmse_deg']:>8.4f}" for r in result["sweep"] if r["data"] == data))
    lines += ["", "Q = q I and R (improved form; the paper: larger Q, smaller RMSE; larger R, larger RMSE):"]
    for key in ("q", "R"):
        cells = [r for r in result["noise_sweeps"] if r["parameter"] == key]
        values = list(dict.fromkeys(r["value"] for r in cells))
        lines.append(f"{'data':<{w}} " + "".join(f"{key + ' = ' + format(v, 'g'):>12}" for v in values))
        for data in dict.fromkeys(r["data"] for r in cells):
            lines.append(f"{data:<{w}} " + "".join(f"{r['rmse_deg']:>12.4f}" for r in cells if r["data"] == data))
    lines += ["", "bit-accurate predictor (the core's integers; formats "
              + ", ".join(f"{k} {v}" for k, v in result["formats"].items()) + "), each filter started from its first "
              "three samples as the paper does, against the float improved form on the same ADC codes and the same "
              "predictions:",
              f"{'data':<{w}} {'RMSE fixed':>10} {'RMSE float':>10} {'predictions':>11} {'max |fixed - float|':>20} "
              f"{'rms':>9} {'overflows':>9} {'not PD':>7}"]
    for r in result["fixed"]:
        lines.append(f"{r['data']:<{w}} {r['rmse_fixed_deg']:>10.4f} {r['rmse_float_deg']:>10.4f} {r['predictions']:>11} "
                     f"{r['max_from_float_deg']:>20.6f} {r['rms_from_float_deg']:>9.6f} {r['overflowed']:>9} "
                     f"{r['not_positive_definite']:>7}")
    if not result["words"]:
        return "\n".join(lines)
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
            line += (f"{c['not_positive_definite']:>5} {c['rmse_deg']:>9.4g}" if "rmse_deg" in c else f"{'(refused)':>15}")
        lines.append(line)
    lines += ["", _word_finding(result), "table 1 has 32 of the paper's 480 samples (it says 40, prints 32); the "
              "synthetic series stands in for the rest, with its noise known."]
    return "\n".join(lines)


def _word_bits(result):
    return sorted({r["operand_bits"] for r in result["words"]})


def _word_grid(result):
    grid = {}
    for r in result["words"]:
        grid.setdefault((r["form"], r["register_frac"]), {})[r["operand_bits"]] = r
    return grid


def roll_claims(options, result, runs):
    """The paper's claims (sec. 3), judged on the synthetic series of every seed (a file: its one
    run) and, where it says something, on table 1 (the same on every seed)."""
    from kfpga.core.claims import Claim, spread

    basic, plain, fading, best = (f[0] for f in _ROLL_FORMS)

    def rmse(run, data, form):
        return next(r["rmse_deg"] for r in run["rows"] if r["data"] == data and r["form"] == form)

    def other(run):
        return next(d for d in dict.fromkeys(r["data"] for r in run["rows"]) if d != TABLE1)

    b = [rmse(run, other(run), basic) for run in runs]
    i = [rmse(run, other(run), best) for run in runs]
    pl = [rmse(run, other(run), plain) for run in runs]
    fa = [rmse(run, other(run), fading) for run in runs]
    t1b, t1i = rmse(result, TABLE1, basic), rmse(result, TABLE1, best)

    def sweep(run, key):
        return [r["rmse_deg"] for r in run["noise_sweeps"] if r["data"] == other(run) and r["parameter"] == key]

    qs, rs = [sweep(run, "q") for run in runs], [sweep(run, "R") for run in runs]
    not_pd = [next(r for r in run["fixed"] if r["data"] == other(run))["not_positive_definite"] for run in runs]
    noise = result["params"]["noise_deg"]
    what = f"synthetic, noise {noise:g} deg" if result["seed"] is not None else other(result)
    return [
        Claim("the basic combined interval predictor: prediction RMSE 0.3935 deg (sec. 3)", "0.3935 deg on its 480 "
              "samples", None, f"{what}: {spread(b)} deg; table 1: {t1b:.4f} deg",
              "the paper's 480 samples are not available (table 1 prints 32)"),
        Claim("the improved predictor: prediction RMSE 0.1173 deg (sec. 3)", "0.1173 deg on its 480 samples", None,
              f"{what}: {spread(i)} deg; table 1: {t1i:.4f} deg",
              "the paper's 480 samples are not available (table 1 prints 32)"),
        Claim("the improvements lower the prediction RMSE (by 0.2762 deg, sec. 3)", "0.3935 -> 0.1173 deg",
              [x < y for x, y in zip(i, b, strict=True)] + [t1i < t1b],
              f"{what}: lowered by {spread([y - x for x, y in zip(i, b, strict=True)])} deg; table 1 by {t1b - t1i:.4f}",
              "every run, and table 1 as one more"),
        Claim("the improved predictor meets the stabiliser's requirement: RMSE < 0.2 deg (sec. 3)", "0.1173 < 0.2",
              [x < ROLL_PAPER["requirement"] for x in i] + [t1i < ROLL_PAPER["requirement"]],
              f"{what}: {spread(i)} deg; table 1 {t1i:.4f} deg",
              "it depends on the series' noise: try --noise 0.1, the sensor accuracy the paper cites"),
        Claim("updating before predicting removes the lag of the basic form (sec. 2)", "said, no figure",
              [x < y for x, y in zip(pl, b, strict=True)], f"RMSE {spread(pl)} deg against the basic form's {spread(b)} deg"),
        Claim("the fading memory (s = 100) keeps new samples effective and lowers the error (sec. 2)", "said, no figure",
              [x < y for x, y in zip(fa, pl, strict=True)], f"RMSE {spread(fa)} deg against {spread(pl)} deg without (s = 1)"),
        Claim("larger Q (its elements), smaller prediction RMSE (sec. 3)", "said, no figure",
              [all(a > c for a, c in itertools.pairwise(q)) for q in qs],
              "q = " + ", ".join(f"{v:g}: {spread([q[k] for q in qs])}" for k, v in enumerate(Q_SWEEP)) + " deg",
              "held when the RMSE falls at each step of q"),
        Claim("larger R, larger prediction RMSE (sec. 3)", "said, no figure",
              [all(a < c for a, c in itertools.pairwise(r)) for r in rs],
              "R = " + ", ".join(f"{v:g}: {spread([r[k] for r in rs])}" for k, v in enumerate(R_SWEEP)) + " deg",
              "held when the RMSE rises at each step of R"),
        Claim("the square root keeps the covariance positive definite (sec. 2)", "said, no figure",
              [n == 0 for n in not_pd], f"updates not positive definite in the core's integers (default formats): "
              f"{spread(not_pd, '.3g')}; the word-length sweep of the first run in the table above",
              "in float64 no form loses it; fixed point is where it matters"),
    ]


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
    return text + "."


def roll_plot(result, path):
    """The paper's figs. 4-5: the roll and its predictions, and the prediction errors; its table 1
    with both forms' predictions; and the word-length sweep."""
    from kfpga.model.plots import pyplot, save_figure

    plt = pyplot()

    data = next(d for d in result["series"] if not d.startswith("table"))
    s = result["series"][data]
    z = s["roll"]
    t = np.arange(len(z)) * result["params"]["T"]
    fig = plt.figure(figsize=(13, 11))
    a = fig.add_subplot(3, 1, 1)
    b = fig.add_subplot(3, 1, 2, sharex=a)
    d = fig.add_subplot(3, 2, 5)
    c = fig.add_subplot(3, 2, 6)
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
    table = result["series"][TABLE1]
    zt = table["roll"]
    tt = np.arange(len(zt)) * result["params"]["T"]
    d.plot(tt, zt, "ko-", ms=3, lw=0.8, label="table 1")
    for name, style in ((_ROLL_FORMS[0][0], "s:"), (_ROLL_FORMS[3][0], "^-.")):
        d.plot(tt[2:], table[name][:-2], style, ms=3, lw=0.9, label=f"predicted, {name}")
    d.set(title="the paper's table 1 and the 1 s predictions", xlabel="time (s)", ylabel="roll (deg)")
    d.legend(loc="best", fontsize=7)
    for (form, frac), cells in _word_grid(result).items():
        bits = [bb for bb in sorted(cells) if "rmse_deg" in cells[bb]]
        share = [100.0 * cells[bb]["not_positive_definite"] / cells[bb]["updates"] for bb in bits]
        c.plot(bits, share, "o-" if form == "sqrt" else "s--", label=f"{'square root' if form == 'sqrt' else 'plain'}, "
                                                                     f"F = {frac}")
    c.set(title=f"covariance not positive definite ({result['words_data']})", xlabel="multiplier operand bits B",
          ylabel="% of updates")
    c.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)




def _add_arguments(parser):
    parser.add_argument("--samples", type=int, metavar="N",
                        help="samples of the synthetic series (default: 480, the paper's count; at least 8)")
    parser.add_argument("--input", metavar="CSV", help="your roll series (deg, one per row every 0.5 s) instead of the "
                                                       "synthetic one: the only or last column, under an optional "
                                                       "header; lines with # are comments")
    parser.add_argument("--noise", type=float, metavar="DEG", help=f"measurement noise of the synthetic series, deg "
                                                                 f"(default: {NOISE:g}; the paper's sensor: 0.1)")
    parser.add_argument("--fading", type=float, metavar="S", help="the fading factor s of the improved form (default: "
                                                                  "the paper's 100; > 0, 1 is none)")
    parser.add_argument("--q", type=float, metavar="Q", help="process noise, Q = q I (default: the paper's 1)")
    parser.add_argument("--r", type=float, metavar="R", help="measurement-noise variance, deg^2 (default: the paper's "
                                                             "0.01)")
    parser.add_argument("--p0", metavar="P", help="each filter's starting covariance: a number for a matrix of it "
                                                  "everywhere (the paper's: 10), or diag:V for V I")
    parser.add_argument("--a-printed", action="store_true",
                        help="the float forms with eq. (22)'s A as printed: the sample period T (0.5 s) in its "
                             "bottom-right corner, not 1")


def _p0(text):
    try:
        if text.startswith("diag:"):
            v = float(text[5:])
            return tuple(tuple(v if i == j else 0.0 for j in range(3)) for i in range(3))
        v = float(text)
        return tuple((v, v, v) for _ in range(3))
    except ValueError:
        raise UsageError(f"--p0 must be a number (every entry) or diag:V, not {text!r}") from None


def _params(options):
    from kfpga.model import roll as rp

    given = {key: value for key, value in (("s", options.fading), ("q", options.q), ("R", options.r),
                                           ("P0", None if options.p0 is None else _p0(options.p0))) if value is not None}
    try:
        return rp.RollParams(**given)
    except (TypeError, ValueError) as exc:
        raise UsageError(f"--fading/--q/--r/--p0: {exc}") from None


def _check(options):
    from kfpga.model import roll as rp

    _params(options)
    if options.input:
        for option in ("samples", "noise"):
            if getattr(options, option) is not None:
                raise UsageError(f"--{option} does not apply with --input: the file is the series")
    elif options.samples is not None and options.samples < rp.MIN_SAMPLES:
        raise UsageError(f"--samples must be at least {rp.MIN_SAMPLES} (each filter starts from 3 samples), not "
                         f"{options.samples}")
    if options.noise is not None and not 0.0 <= options.noise <= 10.0:
        raise UsageError(f"--noise must be in 0..10 deg, not {options.noise:g}")


def _run(options, seed, *, sweep_words=True):
    from kfpga.core.csvio import read_series
    from kfpga.model import roll as rp

    params = _params(options)
    if options.input:
        z = read_series(options.input)
        if len(z) < rp.MIN_SAMPLES:
            raise InputError(f"{options.input}: {len(z)} samples; the interval predictor needs at least {rp.MIN_SAMPLES}")
        return roll(seed=None, samples=len(z), series=(f"{Path(options.input).name} ({len(z)} samples)", z),
                    params=params, printed_a=options.a_printed)
    return roll(seed=seed, samples=480 if options.samples is None else options.samples, params=params,
                noise=NOISE if options.noise is None else options.noise, printed_a=options.a_printed,
                sweep_words=sweep_words)


EVALUATION = Evaluation(
    summary="[Zhang]: the ship-roll interval predictor, basic and improved, on the paper's table 1 and a synthetic "
            "roll series",
    description="Two constant-acceleration Kalman filters on alternate roll samples (T = 0.5 s), each predicting 2 "
                "samples (1 s) ahead: the paper's basic form (predict, then update) and its improvements (update then "
                "predict, fading memory s, square-root covariance), on the 32 samples of its table 1 and on a "
                "synthetic roll series (or a CSV of yours). Prints the prediction RMSE of each form, a sweep over s, "
                "and how they compare with the paper's 0.3935 and 0.1173 deg and its 0.2 deg requirement.",
    add_arguments=_add_arguments,
    check=_check,
    run=_run,
    table=roll_table,
    summary_json=lambda r: {k: r[k] for k in ("seed", "params", "rows", "sweep", "noise_sweeps", "formats", "fixed",
                                              "words")},
    claims=roll_claims,
    # every seed but the first without the word-length sweep (4 s a seed; the claims do not need it)
    measure=lambda options, seed: _run(options, seed, sweep_words=False),
    plot=roll_plot,
    seeded=lambda options: not options.input,
)
