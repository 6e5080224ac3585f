"""Steady moving band heat source on a half-space (2-D line contact): exact, fast table, closed-form fit.

A body moves at speed U in +x under a stationary band |x| <= b that delivers the mean flux
q_bar = Q'/(2b). The dimensionless surface rise theta = dT k/(q_bar b) depends only on X = x/b, the Peclet
number L = U b/(2 chi) and the flux shape f: 'uniform' (f = 1) or 'semi-elliptic' (Hertzian,
f = (4/pi) sqrt(1 - S^2)). Jaeger (1942) Proc. R. Soc. NSW 76:203; Carslaw & Jaeger (1959) ch. 10
(moving sources); docs/theory.md §G4.3:

    theta(X; L) = (1/pi) int_{-1}^{1} f(S) e^{L(X-S)} K0(L|X-S|) dS.

`theta_max`/`theta_avg` are the maximum over the band and its mean over |X| <= 1. The dimensional rise is
dT = theta Q'/(2k). `band_theta_table` is the fast evaluator for time series, `band_fit` the closed-form
all-L fit that numpy, jax.numpy and sympy can all evaluate.
"""
from __future__ import annotations

import functools
import math

import numpy as np


def k0e(z):
    """scipy.special.k0e (the exact integrals' kernel), imported on first call: a run evaluates the shipped table
    and need not load scipy.special."""
    return _special().k0e(z)


@functools.lru_cache(maxsize=None)
def _special():
    import scipy.special
    return scipy.special


def quad(*args, **kwargs):
    """scipy.integrate.quad, imported on first call (a fresh `mechsim run` need not load scipy.integrate)."""
    from scipy.integrate import quad as impl
    return impl(*args, **kwargs)


def minimize_scalar(*args, **kwargs):
    """scipy.optimize.minimize_scalar, imported on first call (a fresh `mechsim run` need not load scipy.optimize)."""
    from scipy.optimize import minimize_scalar as impl
    return impl(*args, **kwargs)

KINDS = ("uniform", "semi-elliptic")
STATISTICS = ("max", "avg")
EULER_GAMMA = 0.57721566490153286

#: Table range (log10 L) and nodes per decade of the fast evaluator; outside it the exact asymptotes hold.
TABLE_LOG10_RANGE = (-4.0, 4.0)
TABLE_NODES_PER_DECADE = 5
#: Max relative error of `band_theta_table` against the exact integral over 1e-3 < L < 1e3 (measured
#: 1.4e-5 worst, for theta_avg; see `band_theta_table`); asserted by tests/test_thermal_band.py.
TABLE_MAX_REL_ERROR = 2e-5


def _check(kind: str, statistic: str | None = None) -> None:
    if kind not in KINDS:
        raise ValueError(f"unknown flux distribution {kind!r}; use one of {KINDS}")
    if statistic is not None and statistic not in STATISTICS:
        raise ValueError(f"unknown statistic {statistic!r}; use one of {STATISTICS}")


def flux_shape(S, kind: str = "uniform"):
    """Flux over the band relative to its mean, f(S), S = x/b in [-1, 1] (mean of f over the band = 1)."""
    _check(kind)
    S = np.asarray(S, dtype=float)
    if kind == "uniform":
        return np.where(np.abs(S) <= 1.0, 1.0, 0.0)
    return (4.0 / np.pi) * np.sqrt(np.clip(1.0 - S * S, 0.0, None))


def _kernel_ahead(v, L):
    """e^{-L v} K0(L v) for v >= 0: flux at S = X + v (ahead of the field point in the body's motion)."""
    return np.exp(-2.0 * L * v) * k0e(L * v)


def _quad(func, a, b, breaks=(), tol=1e-11):
    """quad on [a, b] with extra break points (the kernel varies on the 1/L scale: needed for large L)."""
    if b <= a:
        return 0.0
    pts = sorted({p for p in breaks if a < p < b})
    return quad(func, a, b, points=pts or None, limit=400, epsabs=tol * 1e-2, epsrel=tol)[0]


def _scale_breaks(a, b, L, sign):
    """Points at 0.1/L, 1/L, 10/L from the field point a (sign=+1) or b (sign=-1) inside [a, b]."""
    return [a + c / L if sign > 0 else b - c / L for c in (0.1, 1.0, 10.0)]


def _band_theta_point(x: float, L: float, kind: str) -> float:
    if kind == "uniform":
        behind = _quad(lambda v: k0e(L * v), 0.0, 1.0 + x, _scale_breaks(0.0, 1.0 + x, L, +1))   # S = x - v < x
        ahead = _quad(lambda v: _kernel_ahead(v, L), 0.0, 1.0 - x, _scale_breaks(0.0, 1.0 - x, L, +1))
        return (behind + ahead) / np.pi
    # semi-elliptic: S = sin(phi) removes the square-root end singularities, f dS = (4/pi) cos^2(phi) dphi
    phi_x = math.asin(min(1.0, max(-1.0, x)))
    to_phi = lambda s: math.asin(min(1.0, max(-1.0, s)))
    w = lambda p: (4.0 / np.pi) * math.cos(p) ** 2
    behind = _quad(lambda p: w(p) * k0e(L * (x - math.sin(p))), -0.5 * np.pi, phi_x,
                   [to_phi(x - c / L) for c in (0.1, 1.0, 10.0)])
    ahead = _quad(lambda p: w(p) * _kernel_ahead(math.sin(p) - x, L), phi_x, 0.5 * np.pi,
                  [to_phi(x + c / L) for c in (0.1, 1.0, 10.0)])
    return (behind + ahead) / np.pi


def band_theta(X, L, kind: str = "uniform"):
    """Exact dimensionless surface rise theta(X; L) (quad split at S = X, scipy.special.k0e).

    Jaeger (1942); docs/theory.md §G4.3. The semi-elliptic integral is taken in S = sin(phi) (smooth at the
    band ends). X may be an array (evaluated point by point; for checks, not for time series).
    """
    _check(kind)
    if not L > 0:
        raise ValueError(f"band_theta needs L > 0 (no steady stationary limit in 2-D), got {L!r}")
    return np.vectorize(lambda x: _band_theta_point(float(x), float(L), kind), otypes=[float])(
        np.asarray(X, dtype=float))


def band_theta_max_exact(L: float, kind: str = "uniform") -> tuple[float, float]:
    """(theta_max, X at the maximum) of the exact solution, by bounded Brent search over |X| <= 1."""
    res = minimize_scalar(lambda x: -float(band_theta(x, L, kind)), bounds=(-1.0, 1.0), method="bounded",
                          options={"xatol": 1e-6})
    # the uniform band peaks at the trailing edge as L -> inf; do not miss the end point
    edge = float(band_theta(1.0, L, kind))
    return (edge, 1.0) if edge > -res.fun else (float(-res.fun), float(res.x))


def _band_overlap(u, kind):
    """w(u) = int f(S) over S and S+u both in [-1, 1]: the weight of separation u = X - S in theta_avg."""
    if kind == "uniform":
        cum = lambda s: s
    else:
        cum = lambda s: (2.0 / np.pi) * (s * math.sqrt(max(0.0, 1.0 - s * s)) + math.asin(s))
    return cum(min(1.0, 1.0 - u)) - cum(max(-1.0, -1.0 - u))


def band_theta_avg_exact(L: float, kind: str = "uniform") -> float:
    """Exact band mean of theta, (1/2) int_{-1}^{1} theta dX, as one quad over the separation u = X - S.

    theta_avg = (1/(2 pi)) int_{-2}^{2} w(u) e^{Lu} K0(L|u|) du (docs/theory.md §G4.3, rearranged).
    """
    _check(kind)
    breaks = _scale_breaks(0.0, 2.0, L, +1)
    behind = _quad(lambda u: _band_overlap(u, kind) * k0e(L * u), 0.0, 2.0, breaks)
    ahead = _quad(lambda u: _band_overlap(-u, kind) * _kernel_ahead(u, L), 0.0, 2.0, breaks)
    return (behind + ahead) / (2.0 * np.pi)


def band_theta_exact(L, kind: str = "uniform", statistic: str = "max"):
    """Exact theta_max or theta_avg for scalar or array L (slow: a quadrature per value)."""
    _check(kind, statistic)
    if statistic == "max":
        fn = lambda x: band_theta_max_exact(float(x), kind)[0]
    else:
        fn = lambda x: band_theta_avg_exact(float(x), kind)
    return np.vectorize(fn, otypes=[float])(np.asarray(L, dtype=float))


# ---------------------------------------------------------------------------------------------- asymptotes
def _semi_elliptic_high_profile(x):
    """High-L semi-elliptic profile sqrt(L) theta(X) = (1/sqrt(2 pi)) int_{-1}^{X} f(S)/sqrt(X-S) dS."""
    f = lambda s: float(flux_shape(s, "semi-elliptic"))
    val = quad(f, -1.0, x, weight="alg", wvar=(0.0, -0.5), epsabs=1e-14, epsrel=1e-12)[0]
    return val / math.sqrt(2.0 * math.pi)


@functools.lru_cache(maxsize=None)
def high_peclet_coefficient(kind: str = "uniform", statistic: str = "max") -> float:
    """A in theta -> A/sqrt(L) as L -> inf (1-D penetration limit; docs/theory.md §G4.3).

    uniform: max 2/sqrt(pi) = 1.1284 (trailing edge), avg 4/(3 sqrt(pi)) = 0.7523;
    semi-elliptic: max 1.1115 (at X = 0.652; Blok's 1.11), avg 64/(15 pi^1.5) = 0.7662.
    """
    _check(kind, statistic)
    if kind == "uniform":
        return 2.0 / math.sqrt(math.pi) if statistic == "max" else 4.0 / (3.0 * math.sqrt(math.pi))
    if statistic == "avg":
        return 64.0 / (15.0 * math.pi**1.5)
    return SEMI_ELLIPTIC_HIGH_MAX


def semi_elliptic_high_max() -> float:
    """The semi-elliptic band's A for the maximum: the largest high-L profile over the band, found by quadrature and
    a bounded minimiser (what SEMI_ELLIPTIC_HIGH_MAX holds)."""
    res = minimize_scalar(lambda x: -_semi_elliptic_high_profile(x), bounds=(0.0, 1.0), method="bounded",
                          options={"xatol": 1e-9})
    return float(-res.fun)


#: `semi_elliptic_high_max()` (Blok's 1.11; tests/test_thermal_band.py computes it again): kept as a number so that a
#: run does not load scipy's quadrature and minimiser for a constant
SEMI_ELLIPTIC_HIGH_MAX = 1.1115483780654032


def low_peclet_constant(kind: str = "uniform", statistic: str = "max") -> float:
    """d in theta -> (2/pi)[ln(1/L) + d] as L -> 0 (2-D log growth; docs/theory.md §G4.3), in closed form.

    From K0(z) ~ -ln(z/2) - gamma_E: uniform d_max = 1 + ln 2 - gamma_E = 1.116 (centre),
    d_avg = 3/2 - gamma_E = 0.923; semi-elliptic d_max = 2 ln 2 + 1/2 - gamma_E = 1.309,
    d_avg = 2 ln 2 + 1/6 - gamma_E = 0.976.
    """
    _check(kind, statistic)
    if kind == "uniform":
        return (1.0 + math.log(2.0) - EULER_GAMMA) if statistic == "max" else (1.5 - EULER_GAMMA)
    base = 2.0 * math.log(2.0) - EULER_GAMMA
    return base + (0.5 if statistic == "max" else 1.0 / 6.0)


def band_theta_high(L, kind: str = "uniform", statistic: str = "max"):
    """High-L asymptote A/sqrt(L); docs/theory.md §G4.3."""
    return high_peclet_coefficient(kind, statistic) / np.sqrt(np.asarray(L, dtype=float))


def band_theta_low(L, kind: str = "uniform", statistic: str = "max"):
    """Low-L asymptote (2/pi)[ln(1/L) + d]; docs/theory.md §G4.3."""
    return (2.0 / np.pi) * (np.log(1.0 / np.asarray(L, dtype=float)) + low_peclet_constant(kind, statistic))


# ---------------------------------------------------------------------------------------------- fast table
def table_log_nodes() -> np.ndarray:
    """ln(L) at the fast table's nodes (TABLE_NODES_PER_DECADE per decade over TABLE_LOG10_RANGE)."""
    lo, hi = TABLE_LOG10_RANGE
    n = int(round((hi - lo) * TABLE_NODES_PER_DECADE)) + 1
    return np.linspace(lo, hi, n) * math.log(10.0)


def table_nodes_exact(kind: str, statistic: str) -> np.ndarray:
    """The exact theta at the table's nodes (quadrature: slow, for building and checking the table)."""
    return band_theta_exact(np.exp(table_log_nodes()), kind, statistic)


def table_spline_coefficients(values) -> np.ndarray:
    """The coefficients (4, nodes - 1) of scipy's CubicSpline (not-a-knot) of ln(theta) in ln(L) through the node
    values: row 0 the cubic term, in each interval's local coordinate (scipy.interpolate.PPoly's layout)."""
    from scipy.interpolate import CubicSpline
    return CubicSpline(table_log_nodes(), np.log(np.asarray(values, dtype=float))).c


def evaluate_piecewise_cubic(breaks: np.ndarray, c: np.ndarray, x: np.ndarray, xp=np) -> np.ndarray:
    """A piecewise cubic (scipy.interpolate.PPoly's layout: c[k, i] multiplies (x - breaks[i])^(3-k) on
    breaks[i] <= x < breaks[i+1], the end pieces extended beyond the ends) at x, in numpy with PPoly's own
    interval rule and order of operations (sum of c[3-k] (x - b)^k for k = 0..3, powers by repeated
    multiplication), so it gives scipy's values; tests/test_thermal_band.py compares the two. `xp`: the array
    namespace (numpy, or jax.numpy to differentiate it)."""
    i = xp.clip(xp.searchsorted(breaks, x, side="right") - 1, 0, len(breaks) - 2)
    s = x - breaks[i]
    s2 = s * s
    return ((c[3, i] + c[2, i] * s) + c[1, i] * s2) + c[0, i] * (s2 * s)


@functools.lru_cache(maxsize=None)
def _table(kind: str, statistic: str) -> tuple[np.ndarray, np.ndarray]:
    """(nodes, coefficients) of the spline through the node values: as shipped in band_table_data.py (the values
    `table_nodes_exact` gives and the coefficients `table_spline_coefficients` makes of them, both checked by the
    tests), or computed here when the table's grid has changed."""
    from mechsim.thermal import band_table_data as data
    coefficients = data.COEFFICIENTS.get((kind, statistic))
    if (data.LOG10_RANGE != tuple(TABLE_LOG10_RANGE) or data.NODES_PER_DECADE != TABLE_NODES_PER_DECADE
            or coefficients is None):
        coefficients = table_spline_coefficients(table_nodes_exact(kind, statistic))
    return table_log_nodes(), np.asarray(coefficients, dtype=float)


def band_theta_table(L, kind: str = "semi-elliptic", statistic: str = "max"):
    """Fast theta_max/theta_avg for arrays of L (the evaluator to use at every output instant).

    A cubic spline of ln(theta) in ln(L) through the exact values at 5 nodes per decade on 1e-4..1e4 (the
    values and the spline's coefficients shipped in band_table_data.py); outside that range the exact asymptotes
    `band_theta_high`/`band_theta_low` (relative mismatch at the table ends < 1e-4). Measured max relative
    error against the exact integral over 1e-3 < L < 1e3 (600 log-spaced points): max 2.1e-6 / 3.9e-6
    (uniform / semi-elliptic), avg 1.4e-5 / 1.4e-5; bound asserted: TABLE_MAX_REL_ERROR = 2e-5.
    L = 0 gives +inf (no steady stationary limit in 2-D); L must be >= 0.
    """
    _check(kind, statistic)
    L = np.asarray(L, dtype=float)
    if np.any(L < 0) or np.any(np.isnan(L)):
        raise ValueError("band_theta_table: Peclet numbers must be >= 0")
    lo, hi = (10.0**v for v in TABLE_LOG10_RANGE)
    nodes, coefficients = _table(kind, statistic)
    with np.errstate(divide="ignore"):
        out = np.asarray(np.exp(evaluate_piecewise_cubic(nodes, coefficients, np.log(np.clip(L, lo, hi)))))
        if np.any(L < lo):                 # the asymptotes only where needed: the high one costs a quadrature
            out = np.where(L < lo, band_theta_low(L, kind, statistic), out)
        if np.any(L > hi):
            out = np.where(L > hi, band_theta_high(np.maximum(L, hi), kind, statistic), out)
    return out


def band_theta_table_xp(L, kind: str = "semi-elliptic", statistic: str = "max", xp=np):
    """`band_theta_table` in the array namespace `xp` (numpy or jax.numpy), so that jax can differentiate the
    flash rise (docs/sensitivity.md): the same cubic pieces of ln(theta) in ln(L) (`evaluate_piecewise_cubic` on
    the shipped coefficients) and the same asymptotes outside the table;
    docs/theory.md §G4.3. L > 0."""
    _check(kind, statistic)
    nodes, coef = _table(kind, statistic)
    lo, hi = (10.0**v for v in TABLE_LOG10_RANGE)
    s = xp.log(xp.clip(L, lo, hi))
    inside = xp.exp(evaluate_piecewise_cubic(xp.asarray(nodes), xp.asarray(coef), s, xp))
    low = (2.0 / np.pi) * (xp.log(1.0 / xp.maximum(L, 1e-300)) + low_peclet_constant(kind, statistic))
    high = high_peclet_coefficient(kind, statistic) / xp.sqrt(xp.maximum(L, hi))
    return xp.where(L < lo, low, xp.where(L > hi, high, inside))


# ---------------------------------------------------------------------------------------------- closed-form fit
#: (A', B, m) of the all-L fit theta = (2/pi) ln(1 + g), g = [(A'/sqrt L)^m + (B/L)^m]^(1/m),
#: A' = pi A/2, B = e^d; docs/theory.md §G4.3 (max error 3.0/5.0/2.9/5.1 % over 1e-3 < L < 1e3).
FIT_PARAMETERS = {
    ("uniform", "max"): (1.7725, 3.0526, 1.435),
    ("uniform", "avg"): (1.1816, 2.5163, 2.131),
    ("semi-elliptic", "max"): (1.7460, 3.7028, 1.541),
    ("semi-elliptic", "avg"): (1.2036, 2.6530, 2.170),
}
#: Stated max relative error of `band_fit` over 1e-3 < L < 1e3 (docs/theory.md §G4.3).
FIT_MAX_REL_ERROR = {("uniform", "max"): 0.030, ("uniform", "avg"): 0.050,
                     ("semi-elliptic", "max"): 0.029, ("semi-elliptic", "avg"): 0.051}


def band_fit(L, kind: str = "semi-elliptic", statistic: str = "max", xp=np):
    """Closed-form all-L fit theta ≈ (2/pi) ln(1 + [(A'/sqrt L)^m + (B/L)^m]^(1/m)); docs/theory.md §G4.3.

    Asymptote-matched blend (Muzychka & Yovanovich 2001 style). `xp` is the array namespace: numpy,
    jax.numpy or sympy (then L may be a Symbol and the result is an expression).
    """
    _check(kind, statistic)
    a, b, m = FIT_PARAMETERS[(kind, statistic)]
    g = ((a / xp.sqrt(L)) ** m + (b / L) ** m) ** (1.0 / m)
    return (2 / xp.pi) * xp.log(1 + g)


# ---------------------------------------------------------------------------------------------- transient, stationary band
def band_stationary_transient(X, fourier, kind: str = "uniform"):
    """theta(X, t) of a stationary uniform band switched on at t = 0, Fo = chi t/b^2 (exact, quad).

    From the instantaneous 2-D line source on an insulated half-space (Carslaw & Jaeger 1959 §10.3):
    theta = (1/(2 sqrt pi)) int_0^Fo s^-1/2 [erf((1-X)/(2 sqrt s)) + erf((1+X)/(2 sqrt s))] ds.
    At the centre and large Fo: (1/pi)[ln(4 Fo) + 2 - gamma_E] (docs/theory.md §G4.6).
    """
    if kind != "uniform":
        raise ValueError("band_stationary_transient is implemented for the uniform band only")

    def one(x, fo):
        def g(s):
            r = 0.5 / math.sqrt(s) if s > 0 else math.inf
            return sum(0.0 if a == 0 else math.erf(a * r) for a in (1.0 - x, 1.0 + x))

        split = min(fo, 1.0)
        val = quad(g, 0.0, split, weight="alg", wvar=(-0.5, 0.0), epsabs=1e-13, epsrel=1e-11)[0]
        if fo > split:
            val += quad(lambda s: g(s) / math.sqrt(s), split, fo, limit=400, epsabs=1e-13, epsrel=1e-11)[0]
        return val / (2.0 * math.sqrt(math.pi))

    return np.vectorize(one, otypes=[float])(np.asarray(X, dtype=float), np.asarray(fourier, dtype=float))


def band_stationary_transient_centre_asymptote(fourier):
    """(1/pi)[ln(4 Fo) + 2 - gamma_E]: large-Fo centre rise of the switched-on stationary band (docs/theory.md §G4.6)."""
    return (np.log(4.0 * np.asarray(fourier, dtype=float)) + 2.0 - EULER_GAMMA) / np.pi


def write_table_data(path, values: dict | None = None) -> None:
    """Regenerate band_table_data.py: the exact node values of every kind and statistic (`values`, keyed like
    band_table_data.VALUES, or None to integrate them afresh) and the spline coefficients made of them."""
    from pathlib import Path
    from mechsim.thermal import band_table_data as data
    head = data.__doc__.strip()
    keys = [(kind, statistic) for kind in ("uniform", "semi-elliptic") for statistic in ("max", "avg")]
    values = {key: (values or {}).get(key) for key in keys}
    values = {key: v if v is not None else table_nodes_exact(*key) for key, v in values.items()}

    def block(numbers, indent):
        numbers = [repr(float(x)) for x in numbers]
        return [indent + ", ".join(numbers[i:i + 4]) + "," for i in range(0, len(numbers), 4)]

    lines = [f'"""{head}"""', "", f"LOG10_RANGE = {tuple(TABLE_LOG10_RANGE)!r}",
             f"NODES_PER_DECADE = {TABLE_NODES_PER_DECADE!r}", "", "VALUES = {"]
    for key in keys:
        lines += [f"    {key!r}: ("] + block(values[key], "        ") + ["    ),"]
    lines += ["}", "", "#: table_spline_coefficients(VALUES[key]): rows of the cubic, quadratic, linear and constant terms",
              "COEFFICIENTS = {"]
    for key in keys:
        lines.append(f"    {key!r}: (")
        for row in table_spline_coefficients(values[key]):
            lines += ["        ("] + block(row, "            ") + ["        ),"]
        lines.append("    ),")
    Path(path).write_text("\n".join(lines + ["}"]) + "\n")


if __name__ == "__main__":
    from pathlib import Path
    write_table_data(Path(__file__).with_name("band_table_data.py"))
