"""Bit-accurate fixed-point Kalman filter: the integers the RTL computes, sample by sample.

Both variants run in the datapath's units (``v = T*x2``, ``P' = D P D``, see
:meth:`KalmanParams.scaled`), so T never multiplies inside the loop. Every quantity written to a
register is an exact integer sum or product requantised once into its format
(:data:`kfpga.config.POINTS`), with that format's rounding and overflow rule:

Steady state (constant gains ``k1 = K1``, ``k2 = T*K2``, rounded into ``gain``)::

    xl1 = [x1 + v]_xl1          e = [y - xl1]_e
    x1  = [xl1 + k1*e]_x1       v = [v + k2*e]_v          yhat = xl1

Time-varying (SPEC §1, corrected; ``Q' = T^2 Q`` in ``pl``, ``R`` in ``s``)::

    xl1  = [x1 + v]_xl1
    pl11 = [p11 + p12 + p21 + p22]_pl    pl12 = [p12 + p22]_pl
    pl21 = [p21 + p22]_pl                pl22 = [p22 + Q']_pl
    S    = [pl11 + R]_s
    K1   = div(pl11, S)                  K2   = div(pl21, S)
    e    = [y - xl1]_e
    x1   = [xl1 + K1*e]_x1               v    = [v + K2*e]_v
    p11  = [pl11 - K1*pl11]_p            p12  = [pl12 - K1*pl12]_p
    p21  = [pl21 - K2*pl11]_p            p22  = [pl22 - K2*pl12]_p

``div(n, d)`` is what the RTL's restoring divider computes: the quotient ``|n|/d`` truncated to
``gain.frac_bits`` fraction bits (``floor(|n_raw| * 2**sh / d_raw)``, ``sh = gain.frac +
s.frac - pl.frac``), saturated to ``gain``'s largest value when it does not fit (or when
``d <= 0``), then given the sign of ``n``: truncation toward zero.

The output ``x2 = v / T`` is ``[v]_x2`` read with the binary point moved by k when ``T = 2**k``
(a shift), else ``[[v]_vt * (1/T)]_x2`` with ``1/T`` rounded into ``inv_t`` and ``v`` rounded
into the 18-bit operand ``vt`` first. Any saturation (or wrap) sets the sample's overflow flag;
the sticky flag is its running OR.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kfpga.config import INPUT_FORMAT, KalmanConfig
from kfpga.fixed import make_requantizer, to_raw

__all__ = ["Datapath", "KalmanState", "KalmanResult", "FixedKalman", "divide"]


def _align(*fracs):
    """Common fraction bits of an exact sum and the left shift of each term."""
    frac = max(fracs)
    return frac, [frac - f for f in fracs]


@dataclass(frozen=True)
class Datapath:
    """Every constant, shift and bound of the datapath, derived once from a config.

    The RTL (``hw/kalman.py``) reads the same fields, so model and hardware cannot drift.
    """

    config: KalmanConfig
    variant: str

    def __post_init__(self):
        cfg, f = self.config, self.config.formats
        cfg.require_variant(self.variant)
        scaled = cfg.params.scaled()
        s = object.__setattr__
        if self.variant == "steady":
            k1, k2 = cfg.steady_gain
            s(self, "k1", to_raw(k1, f["gain"])[0])
            s(self, "k2", to_raw(k2, f["gain"])[0])
        s(self, "q", to_raw(scaled.Q, f["pl"])[0])
        s(self, "r", to_raw(cfg.params.R, f["s"])[0])
        s(self, "p0", tuple(to_raw(v, f["p"])[0] for v in (*scaled.P0[0], *scaled.P0[1])))
        s(self, "x0", (to_raw(scaled.x0[0], f["x1"])[0], to_raw(scaled.x0[1], f["v"])[0]))
        # x2 = v / T: a shift when T = 2**k, a product by 1/T otherwise
        k = cfg.t_shift
        s(self, "t_shift", k)
        if k is None:
            s(self, "inv_t", to_raw(1.0 / cfg.params.T, f["inv_t"])[0])
            s(self, "x2_src_frac", f["vt"].frac_bits + f["inv_t"].frac_bits)
        else:
            s(self, "inv_t", None)
            s(self, "x2_src_frac", f["v"].frac_bits + k)
        # fraction bits and operand shifts of each exact sum
        fg, fe, fpl = f["gain"].frac_bits, f["e"].frac_bits, f["pl"].frac_bits
        s(self, "xl1_sum", _align(f["x1"].frac_bits, f["v"].frac_bits))
        s(self, "e_sum", _align(INPUT_FORMAT.frac_bits, f["xl1"].frac_bits))
        s(self, "x1_sum", _align(f["xl1"].frac_bits, fg + fe))
        s(self, "v_sum", _align(f["v"].frac_bits, fg + fe))
        s(self, "p_sum", _align(fpl, fg + fpl))
        s(self, "pl22_sum", _align(f["p"].frac_bits, fpl))
        s(self, "s_sum", _align(fpl, f["s"].frac_bits))
        s(self, "div_shift", fg + f["s"].frac_bits - fpl)
        s(self, "quotient_bits", f["gain"].width - 1)

    def requantizers(self, vector):
        """Requantiser closures for every write of the datapath."""
        f = self.config.formats

        def rq(src_frac, name):
            return make_requantizer(src_frac, f[name], vector=vector)

        out = {
            "xl1": rq(self.xl1_sum[0], "xl1"),
            "e": rq(self.e_sum[0], "e"),
            "x1": rq(self.x1_sum[0], "x1"),
            "v": rq(self.v_sum[0], "v"),
            "x2": rq(self.x2_src_frac, "x2"),
        }
        if self.inv_t is not None:
            out["vt"] = rq(f["v"].frac_bits, "vt")
        if self.variant == "full":
            out["pl"] = rq(f["p"].frac_bits, "pl")
            out["pl22"] = rq(self.pl22_sum[0], "pl")
            out["s"] = rq(self.s_sum[0], "s")
            out["p"] = rq(self.p_sum[0], "p")
        return out


def divide(num, den, shift, quotient_bits):
    """The restoring divider's result (see module docstring); ints or int64 arrays.

    Returns ``(quotient, overflowed)``.
    """
    limit = (1 << quotient_bits) - 1
    if isinstance(num, np.ndarray) or isinstance(den, np.ndarray):
        num, den = np.broadcast_arrays(np.asarray(num, dtype=np.int64), np.asarray(den, dtype=np.int64))
        mag = np.abs(num) << shift
        bad = (den <= 0) | (mag >= (np.maximum(den, 1) << quotient_bits))
        quo = np.where(bad, limit, mag // np.maximum(den, 1))
        return np.where(num < 0, -quo, quo), bad
    mag = abs(num) << shift
    if den <= 0 or mag >= den << quotient_bits:
        quo, bad = limit, True
    else:
        quo, bad = mag // den, False
    return (-quo if num < 0 else quo), bad


@dataclass
class KalmanState:
    """Registers of one or many channels (ints, or int64 arrays of the batch shape)."""

    x1: object
    v: object
    p: tuple = ()  # (p11, p12, p21, p22), full variant only
    sticky: object = False


@dataclass
class KalmanResult:
    """Raw outputs (int64 arrays shaped like the input) and the final state.

    ``x1``, ``yhat`` are in the ``x1``/``xl1`` formats, ``x2`` in ``x2``; ``overflow`` is the
    per-sample flag and ``sticky`` its running OR.
    """

    x1: np.ndarray
    x2: np.ndarray
    yhat: np.ndarray
    overflow: np.ndarray
    sticky: np.ndarray
    state: KalmanState


class FixedKalman:
    """The bit-accurate filter of one variant for one config.

    Parameters
    ----------
    config:
        Formats and model parameters.
    variant:
        ``"steady"`` (constant K_inf) or ``"full"`` (time-varying gain).
    """

    def __init__(self, config=None, *, variant="steady"):
        self.config = KalmanConfig() if config is None else config
        self.variant = variant
        self.datapath = Datapath(self.config, variant)
        self._rq_int = self.datapath.requantizers(vector=False)
        self._rq_vec = self.datapath.requantizers(vector=True)

    def initial_state(self, batch_shape=()):
        d = self.datapath
        if batch_shape == ():
            return KalmanState(d.x0[0], d.x0[1], d.p0 if self.variant == "full" else (), False)

        def full(v):
            return np.full(batch_shape, v, dtype=np.int64)

        p = tuple(full(v) for v in d.p0) if self.variant == "full" else ()
        return KalmanState(full(d.x0[0]), full(d.x0[1]), p, np.zeros(batch_shape, dtype=bool))

    def run(self, y, state=None):
        """Filter raw ADC codes ``y`` (shape ``(n,)`` or ``(..., n)``, time last).

        ``state`` continues a previous run (its ``KalmanResult.state``); by default every
        channel starts from x0, P0.
        """
        y = np.asarray(y)
        if y.dtype.kind not in "iu":
            raise TypeError(f"y must hold integer ADC codes, not {y.dtype}")
        if y.size and (y.min() < INPUT_FORMAT.min_raw or y.max() > INPUT_FORMAT.max_raw):
            raise ValueError(f"y must be within the signed 16-bit ADC range [{INPUT_FORMAT.min_raw}, {INPUT_FORMAT.max_raw}]")
        kernel = _steady_kernel if self.variant == "steady" else _full_kernel
        n = y.shape[-1]
        if y.ndim == 1:
            st = self.initial_state() if state is None else state
            outs = [[0] * n for _ in range(4)]
            st = kernel(self.datapath, self._rq_int, y.tolist(), st, outs, divide)
            arrays = [np.array(o, dtype=np.int64) for o in outs[:3]] + [np.array(outs[3], dtype=bool)]
        else:
            batch = y.shape[:-1]
            st = self.initial_state(batch) if state is None else state
            outs = [np.empty((n, *batch), dtype=np.int64) for _ in range(3)] + [np.empty((n, *batch), dtype=bool)]
            st = kernel(self.datapath, self._rq_vec, np.moveaxis(y.astype(np.int64), -1, 0), st, outs, divide)
            arrays = [np.moveaxis(o, 0, -1) for o in outs]
        x1, x2, yhat, ovf = arrays
        sticky0 = np.asarray(state.sticky if state is not None else False, dtype=bool)
        sticky = np.logical_or.accumulate(ovf, axis=-1) | sticky0[..., None] if n else ovf.copy()
        st.sticky = sticky[..., -1].copy() if n else sticky0
        return KalmanResult(x1, x2, yhat, ovf, sticky, st)

    def run_channels(self, y, channel, states=None):
        """Filter an interleaved multi-channel stream: each channel keeps its own state.

        ``states`` maps channel -> :class:`KalmanState` and is updated in place.
        Returns raw ``(x1, x2, yhat, overflow)`` arrays in input order.
        """
        y, channel = np.asarray(y), np.asarray(channel)
        states = {} if states is None else states
        outs = [np.zeros(len(y), dtype=np.int64) for _ in range(3)] + [np.zeros(len(y), dtype=bool)]
        for ch in np.unique(channel):
            idx = np.flatnonzero(channel == ch)
            res = self.run(y[idx], states.get(int(ch)))
            states[int(ch)] = res.state
            for out, part in zip(outs, (res.x1, res.x2, res.yhat, res.overflow), strict=True):
                out[idx] = part
        return outs

    def to_float(self, result):
        """``(x1, x2, yhat)`` of a result in input units."""
        f = self.config.formats
        return f["x1"].to_float(result.x1), f["x2"].to_float(result.x2), f["xl1"].to_float(result.yhat)


def _x2(q_x2, q_vt, inv_t, v):
    """x2 = v / T: requantised v, or [v]_vt * (1/T) requantised."""
    if inv_t is None:
        return q_x2(v)
    vt, f1 = q_vt(v)
    x2, f2 = q_x2(vt * inv_t)
    return x2, f1 | f2


def _steady_kernel(d, rq, ys, st, outs, _divide):
    """Steady-state update for every time step of ``ys`` (ints or batch rows)."""
    q_xl1, q_e, q_x1, q_v, q_x2, q_vt = rq["xl1"], rq["e"], rq["x1"], rq["v"], rq["x2"], rq.get("vt")
    (_, (a_x1, a_v)), (_, (a_y, a_xl)) = d.xl1_sum, d.e_sum
    (_, (b_xl, b_p)), (_, (c_v, c_p)) = d.x1_sum, d.v_sum
    k1, k2, inv_t = d.k1, d.k2, d.inv_t
    o_x1, o_x2, o_yhat, o_ovf = outs
    x1, v = st.x1, st.v
    for n, y in enumerate(ys):
        xl1, f1 = q_xl1((x1 << a_x1) + (v << a_v))            # xl1 = x1 + v
        e, f2 = q_e((y << a_y) - (xl1 << a_xl))                # e = y - xl1
        x1, f3 = q_x1((xl1 << b_xl) + ((k1 * e) << b_p))      # x1 = xl1 + K1 e
        v, f4 = q_v((v << c_v) + ((k2 * e) << c_p))           # v = v + T K2 e
        x2, f5 = _x2(q_x2, q_vt, inv_t, v)                     # x2 = v / T
        o_x1[n], o_x2[n], o_yhat[n], o_ovf[n] = x1, x2, xl1, f1 | f2 | f3 | f4 | f5
    st.x1, st.v = x1, v
    return st


def _full_kernel(d, rq, ys, st, outs, divide_fn):
    """Time-varying update for every time step of ``ys`` (ints or batch rows)."""
    q_xl1, q_e, q_x1, q_v, q_x2, q_vt = rq["xl1"], rq["e"], rq["x1"], rq["v"], rq["x2"], rq.get("vt")
    q_pl, q_pl22, q_s, q_p = rq["pl"], rq["pl22"], rq["s"], rq["p"]
    (_, (a_x1, a_v)), (_, (a_y, a_xl)) = d.xl1_sum, d.e_sum
    (_, (b_xl, b_p)), (_, (c_v, c_p)) = d.x1_sum, d.v_sum
    (_, (g_pl, g_p)), (_, (h_p, h_q)), (_, (s_pl, s_r)) = d.p_sum, d.pl22_sum, d.s_sum
    qc, rc, dsh, qbits, inv_t = d.q, d.r, d.div_shift, d.quotient_bits, d.inv_t
    o_x1, o_x2, o_yhat, o_ovf = outs
    x1, v = st.x1, st.v
    p11, p12, p21, p22 = st.p
    for n, y in enumerate(ys):
        # time update
        xl1, f1 = q_xl1((x1 << a_x1) + (v << a_v))            # xl1 = x1 + v
        pl11, f2 = q_pl(p11 + p12 + p21 + p22)                 # pl11 = p11 + (p12 + p21) + p22
        pl12, f3 = q_pl(p12 + p22)                             # pl12 = p12 + p22
        pl21, f4 = q_pl(p21 + p22)                             # pl21 = p21 + p22
        pl22, f5 = q_pl22((p22 << h_p) + (qc << h_q))          # pl22 = p22 + Q'
        # gain
        s, f6 = q_s((pl11 << s_pl) + (rc << s_r))              # S = pl11 + R
        k1, f7 = divide_fn(pl11, s, dsh, qbits)                # K1 = pl11 / S
        k2, f8 = divide_fn(pl21, s, dsh, qbits)                # K2 = pl21 / S
        # measurement update
        e, f9 = q_e((y << a_y) - (xl1 << a_xl))                # e = y - xl1
        x1, f10 = q_x1((xl1 << b_xl) + ((k1 * e) << b_p))     # x1 = xl1 + K1 e
        v, f11 = q_v((v << c_v) + ((k2 * e) << c_p))          # v = v + K2 e
        p11, f12 = q_p((pl11 << g_pl) - ((k1 * pl11) << g_p))  # p11 = pl11 - K1 pl11
        p12, f13 = q_p((pl12 << g_pl) - ((k1 * pl12) << g_p))  # p12 = pl12 - K1 pl12
        p21, f14 = q_p((pl21 << g_pl) - ((k2 * pl11) << g_p))  # p21 = pl21 - K2 pl11
        p22, f15 = q_p((pl22 << g_pl) - ((k2 * pl12) << g_p))  # p22 = pl22 - K2 pl12
        x2, f16 = _x2(q_x2, q_vt, inv_t, v)                    # x2 = v / T
        flags = f1 | f2 | f3 | f4 | f5 | f6 | f7 | f8 | f9 | f10 | f11 | f12 | f13 | f14 | f15 | f16
        o_x1[n], o_x2[n], o_yhat[n], o_ovf[n] = x1, x2, xl1, flags
    st.x1, st.v, st.p = x1, v, (p11, p12, p21, p22)
    return st
