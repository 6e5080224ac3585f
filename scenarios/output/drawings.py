"""A mechanism's drawing on a figure's axes, scaled to its run: the arrow's length from the run's typical peak force
(99th percentile of |force| while in contact, so that a few impact spikes do not shrink it to nothing; longer arrows
are cut at ARROW_CLIP times that length), coloured by the contact temperature where the run has one. Each mechanism
names its drawing (`Mechanism.drawing`, in its own folder; `mechanisms/drawing.py` says what a drawing is)."""
from __future__ import annotations

import numpy as np
import pandas as pd
from matplotlib.colors import Normalize


def drawing_for(ax, mech, df: pd.DataFrame, with_temperature: bool = True):
    """The drawing of `mech` on `ax`, its arrow scaled to the typical peak force of `df`, coloured by the contact
    temperature range of `df` where it has one; None if the mechanism has no drawing."""
    cls = mech.drawing_class()
    if cls is None:
        return None
    col = cls.force_column
    force = np.abs(df[col].to_numpy(float)) if col in df else np.zeros(0)
    force = force[np.isfinite(force) & (force > 0)]
    peak = float(np.percentile(force, 99)) if force.size else 0.0
    norm = None
    if with_temperature and "temp_contact_C" in df and df["temp_contact_C"].notna().any():
        lo, hi = float(np.nanmin(df["temp_contact_C"])), float(np.nanmax(df["temp_contact_C"]))
        norm = Normalize(lo, hi if hi > lo else lo + 1.0)
    return cls(ax, mech, force_peak=peak or None, temperature=norm, trace=df)
