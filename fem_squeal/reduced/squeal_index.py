"""Which unstable modes will be heard: the sound power level of a mode's ERP, the squeal index, and
1/3-octave band summaries (plain NumPy; the ERP itself: :mod:`fem_squeal.fe.radiation`).

    L_W = 10 log10(ERP / 1 pW)                       [dB re 1 pW]
    SI  = L_W + 10 log10(Re λ / (1 s⁻¹))             [dB]   (unstable modes: Re λ > 0)

The squeal index ranks the unstable modes by growth rate and radiated power with equal weight in
decibels: a mode that grows ten times faster counts as much as one that radiates ten times more
power at the same kinetic energy.  It is a ranking number, not a sound level: the amplitude a mode
reaches (its limit cycle) is not known from a linear analysis, only how fast it grows (Re λ) and how
well it radiates (ERP at the stated kinetic energy).  The 1/3-octave bands are those of IEC 61260
(base 10: centres 1000·10^(n/10) Hz, edges at ×10^(±1/20)), named by their nominal centres; SAE
J2521 counts squeal between 1.25 and 16 kHz.
"""
from __future__ import annotations

import numpy as np

P_REF = 1e-12   # [W]
#: nominal centre frequencies [Hz] of the 1/3-octave bands from 1 to 16 kHz (IEC 61260)
THIRD_OCTAVE_NOMINAL = (1000, 1250, 1600, 2000, 2500, 3150, 4000, 5000, 6300, 8000, 10000, 12500, 16000)


def level_db(power_w, p_ref: float = P_REF) -> np.ndarray:
    """10 log10(P / p_ref) [dB re 1 pW] (−inf for P = 0)."""
    with np.errstate(divide="ignore"):
        return 10.0 * np.log10(np.asarray(power_w, dtype=float) / p_ref)


def squeal_index(real_part, level: np.ndarray) -> np.ndarray:
    """SI = L_W + 10 log10(Re λ · 1 s) of each mode (module docstring); NaN where Re λ ≤ 0."""
    g = np.asarray(real_part, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(g > 0, np.asarray(level, dtype=float) + 10.0 * np.log10(np.where(g > 0, g, 1.0)), np.nan)


def ranking(index: np.ndarray, unstable: np.ndarray) -> list[int]:
    """The unstable modes (indices), highest squeal index first."""
    idx = [int(j) for j in np.flatnonzero(np.asarray(unstable, bool)) if np.isfinite(index[j])]
    return sorted(idx, key=lambda j: -index[j])


def third_octave_bands() -> list[tuple[int, float, float]]:
    """(nominal centre, lower edge, upper edge) [Hz] of the 1/3-octave bands 1-16 kHz."""
    out = []
    for k, nominal in enumerate(THIRD_OCTAVE_NOMINAL):
        fc = 1000.0 * 10.0 ** (k / 10.0)
        out.append((nominal, fc * 10.0 ** (-1 / 20), fc * 10.0 ** (1 / 20)))
    return out


def band_summary(freqs_hz, level, unstable, index) -> list[dict]:
    """Per 1/3-octave band (1-16 kHz): the modes in it, the unstable ones, the highest L_W of all and
    of the unstable modes [dB re 1 pW] and the highest squeal index (None where there is none)."""
    f, L, un, si = (np.asarray(a) for a in (freqs_hz, level, unstable, index))
    out = []
    for nominal, lo, hi in third_octave_bands():
        inside = (f >= lo) & (f < hi)
        u = inside & un.astype(bool)
        out.append({"band_hz": nominal, "lower_hz": lo, "upper_hz": hi, "n_modes": int(inside.sum()),
                    "n_unstable": int(u.sum()),
                    "max_level_db": float(L[inside].max()) if inside.any() else None,
                    "max_unstable_level_db": float(L[u].max()) if u.any() else None,
                    "max_squeal_index_db": float(si[u].max()) if u.any() else None})
    return out
