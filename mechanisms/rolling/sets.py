"""Named parameter sets of the rolling-pair 4-bar (docs/theory.md §K2.2 table, §2.5 K7).

Lengths in m (the paper's lengths are unitless; one unit = 1 m, as in docs/theory.md §K3), angles in rad.
A0 is the origin; the circle sets start with the contact at gamma0 = 0.
Each entry is a plain dict: `make(name)` builds the `RollingFourBar`.
"""
from __future__ import annotations

import math

from mechsim.mechanisms.rolling.pair import CircleOnCircle, CircleOnLine, RollingFourBar

#: docs/theory.md §K2.2 set A: bicursal, two closed monochromatic curves; R/r = 2, period 6 pi.
SET_A = dict(profile="circle", R=2.0, r=1.0, O=(0.5, 0.3), gamma0=0.0, psi=0.3,
             l2=3.0, l3=3.5, l4=1.6, lc=2.0, alpha=math.radians(40.0))

#: set B: multi-cursal, 4 closure intervals -> 4 dichromatic components; R/r = 3, period 8 pi.
SET_B = dict(profile="circle", R=3.0, r=1.0, O=(1.5, 0.2), gamma0=0.0, psi=0.2,
             l2=2.0, l3=3.2, l4=1.8, lc=1.5, alpha=0.5)

#: set C: cusp case l4 = r; bicursal with 3 cusps per branch.
SET_C = dict(profile="circle", R=3.0, r=1.0, O=(1.0, 0.5), gamma0=0.0, psi=0.5,
             l2=3.0, l3=4.0, l4=1.0, lc=2.0, alpha=math.radians(-30.0))

#: set D: circle on the line y = -2, phi in [-6 pi, 0]; l4 = r (cusps). docs/theory.md (Part K) does not state the
#: initial contact; (-6, -2) reproduces its closure intervals and cusps (the contact moves to +x).
SET_D = dict(profile="line", r=1.0, P0=(-6.0, -2.0), tangent=0.0, psi=0.7,
             l2=3.0, l3=3.5, l4=1.0, lc=1.5, alpha=math.radians(20.0), span=(-6.0 * math.pi, 0.0))

#: docs/theory.md §K1.3 (K7): bicursal although the trochoid's bounding annulus (seen from A0: [2, 6]) is not
#: inside the dyad annulus [2.0079, 6.0023]; the trochoid itself stays in [2.0179, 5.9923].
#: (lc, alpha not given there; chosen here.)
SET_BICURSAL_K7 = dict(profile="circle", R=3.0, r=1.0, O=(1.0, 0.0), gamma0=0.0, psi=0.465,
                       l2=4.0051, l3=1.9972, l4=1.0, lc=1.0, alpha=0.0)

#: irrational radius ratio R/r = sqrt(2): never closes; tabulated over a finite span (3 turns of B0).
SET_IRRATIONAL = dict(profile="circle", R=math.sqrt(2.0), r=1.0, O=(0.5, 0.3), gamma0=0.0, psi=0.3,
                      l2=3.0, l3=3.5, l4=1.2, lc=2.0, alpha=math.radians(40.0), n_revolutions=3)

SETS = {
    "A": SET_A,
    "B": SET_B,
    "C": SET_C,
    "D": SET_D,
    "bicursal": SET_A,
    "multi_component": SET_B,
    "cusp": SET_C,
    "bicursal_K7": SET_BICURSAL_K7,
    "irrational": SET_IRRATIONAL,
}


def make(spec: str | dict, **overrides) -> RollingFourBar:
    """Build a `RollingFourBar` from a set name (see SETS) or a dict like the ones above."""
    p = dict(SETS[spec]) if isinstance(spec, str) else dict(spec)
    p.update(overrides)
    name = spec if isinstance(spec, str) else p.pop("name", "")
    if p.pop("profile") == "circle":
        pair = CircleOnCircle(R=p.pop("R"), r=p.pop("r"), O=tuple(p.pop("O")), gamma0=p.pop("gamma0", 0.0))
    else:
        pair = CircleOnLine(r=p.pop("r"), P0=tuple(p.pop("P0")), tangent=p.pop("tangent", 0.0))
    return RollingFourBar(pair=pair, name=name, **p)
