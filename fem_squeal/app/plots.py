"""Matplotlib figures (Agg backend, rank 0 only), saved atomically as PNG, each with the data it
draws as CSV next to it (same name, ``.csv``: :func:`figure_data`)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from fem_squeal.reduced.eigensolve import TWO_PI, unstable
from fem_squeal.util.atomic import columns_of, save_figure_atomic, write_csv_atomic

#: the columns of a plot's CSV (one row per drawn point, bar or polygon corner)
CSV_HEADER = ["panel", "title", "xlabel", "ylabel", "series", "x", "y", "value"]


def pyplot():
    """matplotlib.pyplot on the non-interactive Agg backend (plots, reports and benchmarks)."""
    import matplotlib  # heavy: matplotlib (plots only)

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # heavy: matplotlib (plots only)

    return plt


def _ticks(ax, which: str) -> dict[float, str]:
    ticks = ax.get_yticks() if which == "y" else ax.get_xticks()
    labels = ax.get_yticklabels() if which == "y" else ax.get_xticklabels()
    return {round(float(t), 9): lab.get_text() for t, lab in zip(ticks, labels) if lab.get_text()}


def figure_data(fig) -> list[list]:
    """What the axes of ``fig`` draw, as rows of :data:`CSV_HEADER`: the points of its lines in data
    coordinates (not the reference lines axhline/axvline), its scatter points (value: their colour
    value), its mesh cells (pcolormesh: centre and value), its bars (x and height, or the bar's tick
    label and length for barh) and the corners of its polygons (stackplot, step histograms).
    Colour-bar axes are left out; contour fills are not read (a plot of them gives its own data)."""
    from matplotlib.collections import PathCollection, PolyCollection, QuadMesh  # heavy: matplotlib
    from matplotlib.container import BarContainer  # heavy: matplotlib (plots only)
    from matplotlib.patches import Polygon  # heavy: matplotlib (plots only)

    rows: list[list] = []
    panels = [ax for ax in fig.axes if not hasattr(ax, "_colorbar")]
    for p, ax in enumerate(panels):
        head = [p, ax.get_title(), ax.get_xlabel(), ax.get_ylabel()]

        def add(series, xs, ys, values=None, head=head):
            vals = [""] * len(xs) if values is None else list(values)
            rows.extend([*head, series, float(x), float(y), v] for x, y, v in zip(xs, ys, vals))

        for i, line in enumerate(ax.get_lines()):
            if line.get_transform() != ax.transData:
                continue
            xy = np.asarray(line.get_xydata(), dtype=float)
            label = line.get_label()
            add(label if not label.startswith("_") else f"line {i}", xy[:, 0], xy[:, 1])
        for i, c in enumerate(ax.collections):
            label = c.get_label() if not c.get_label().startswith("_") else f"collection {i}"
            arr = c.get_array()
            if isinstance(c, QuadMesh):
                xy = c.get_coordinates()
                centre = 0.25 * (xy[:-1, :-1] + xy[1:, :-1] + xy[:-1, 1:] + xy[1:, 1:])
                add(label, centre[..., 0].ravel(), centre[..., 1].ravel(), np.asarray(arr).ravel())
            elif isinstance(c, PolyCollection):
                for k, path in enumerate(c.get_paths()):
                    add(f"{label} {k}" if len(c.get_paths()) > 1 else label, path.vertices[:, 0],
                        path.vertices[:, 1])
            elif isinstance(c, PathCollection) and c.get_offset_transform() == ax.transData:
                off = np.asarray(c.get_offsets(), dtype=float).reshape(-1, 2)
                add(label, off[:, 0], off[:, 1], None if arr is None or len(arr) != len(off) else arr)
        yt, xt = _ticks(ax, "y"), _ticks(ax, "x")
        for i, bars in enumerate(c for c in ax.containers if isinstance(c, BarContainer)):
            label = bars.get_label() if not str(bars.get_label()).startswith("_") else f"bars {i}"
            for r in bars.patches:
                if getattr(bars, "orientation", "vertical") == "horizontal":
                    y = r.get_y() + r.get_height() / 2
                    add(yt.get(round(y, 9), label), [r.get_x() + r.get_width()], [y])
                else:
                    x = r.get_x() + r.get_width() / 2
                    add(xt.get(round(x, 9), label), [x], [r.get_y() + r.get_height()])
        for i, patch in enumerate(q for q in ax.patches if isinstance(q, Polygon)):
            xy = patch.get_xy()
            label = patch.get_label() if not patch.get_label().startswith("_") else f"polygon {i}"
            add(label, xy[:, 0], xy[:, 1])
    return rows


def save(fig, path: Path, data: tuple[list[str], list] | None = None) -> None:
    """The figure as PNG at ``path`` and its data as CSV next to it: ``data`` (header, columns) when
    given, else what :func:`figure_data` reads from the figure."""
    save_figure_atomic(fig, path)
    csv = Path(path).with_suffix(".csv")
    if data is not None:
        write_csv_atomic(csv, *data)
    else:
        rows = figure_data(fig)
        write_csv_atomic(csv, CSV_HEADER, columns_of(rows, len(CSV_HEADER)))


def contact_pressure(path: Path, data: dict[str, tuple[np.ndarray, np.ndarray]], title: str = "") -> None:
    """One panel per contact interface: the pressure [MPa] at the slave quadrature points,
    seen along the axis (x, y in mm), interpolated on their Delaunay triangulation."""
    plt = pyplot()
    n = max(len(data), 1)
    fig, axes = plt.subplots(1, n, figsize=(5.0 * n, 4.2), squeeze=False)
    vmax = max((float(p.max()) for _, p in data.values() if len(p)), default=1.0) / 1e6 or 1.0
    for ax, (name, (x, p)) in zip(axes[0], data.items()):
        if len(p) >= 3:
            tc = ax.tricontourf(1e3 * x[:, 0], 1e3 * x[:, 1], p / 1e6, levels=np.linspace(0, vmax, 21),
                                cmap="viridis")
            fig.colorbar(tc, ax=ax, label="contact pressure [MPa]")
        ax.set_aspect("equal")
        ax.set_xlabel("x [mm]")
        ax.set_ylabel("y [mm]")
        ax.set_title(name)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    names = [name for name, (_, p) in data.items() for _ in range(len(p))]
    xy = np.concatenate([x[:, :2] for x, _ in data.values()]) if names else np.empty((0, 2))
    save(fig, path, (["interface", "x_m", "y_m", "pressure_pa"],
                     [names, xy[:, 0], xy[:, 1], np.concatenate([p for _, p in data.values()]) if names else []]))
    plt.close(fig)


def _labels_apart(ax, marks: list[tuple[float, float, str]], gap: float = 0.045) -> None:
    """Annotate points (x, y, text) of ``ax`` with labels moved apart vertically (at least ``gap`` of the
    axes height between two labels closer than 0.2 of its width), each joined to its point by a line."""
    if not marks:
        return
    ax.relim()
    ax.autoscale_view()
    to_axes = ax.transData + ax.transAxes.inverted()
    placed: list[tuple[float, float]] = []
    for x, y, text in sorted(marks, key=lambda m: m[1]):
        xa, ya = to_axes.transform((x, y))
        for px, py in placed:
            if abs(px - xa) < 0.2 and ya < py + gap:
                ya = py + gap
        placed.append((xa, ya))
        ax.annotate(text, (x, y), xytext=(xa, min(ya, 0.98)), textcoords="axes fraction", fontsize=7,
                    arrowprops={"arrowstyle": "-", "color": "0.5", "lw": 0.5})


def root_locus(path: Path, values: np.ndarray, lam: np.ndarray, unstable: np.ndarray, xlabel: str,
               band_hz: tuple[float, float], labels: list[str] | None = None, title: str = "") -> None:
    """Frequency and real part of every tracked branch against the swept parameter (seed 001
    Figs. 3-4, 8): stable points grey, unstable points red; branches inside ``band_hz`` only."""
    plt = pyplot()
    f = lam.imag / TWO_PI
    keep = np.flatnonzero(np.any((f >= band_hz[0]) & (f <= band_hz[1]), axis=0))
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 8), sharex=True)
    marks = []
    for j in keep:
        a1.plot(values, f[:, j], "-", color="0.75", lw=0.7)
        a2.plot(values, lam[:, j].real, "-", color="0.75", lw=0.7)
        u = unstable[:, j]
        if u.any():
            a1.plot(values[u], f[u, j], ".", color="tab:red", ms=3)
            a2.plot(values[u], lam[u, j].real, ".", color="tab:red", ms=3)
            if labels:
                k = np.flatnonzero(u)[np.argmax(lam[u, j].real)]     # the branch's peak growth
                marks.append((values[k], lam[k, j].real, labels[j]))
    _labels_apart(a2, marks)
    a1.set_ylabel("frequency [Hz]")
    a1.set_ylim(*band_hz)
    a2.set_ylabel("Re λ [1/s]")
    a2.set_xlabel(xlabel)
    a2.axhline(0.0, color="k", lw=0.5)
    if title:
        a1.set_title(title)
    fig.tight_layout()
    save(fig, path)
    plt.close(fig)


def complex_plane(path: Path, lam: np.ndarray, band_hz: tuple[float, float], growth_tol: float = 1e-6,
                  title: str = "") -> None:
    """All eigenvalues of a sweep in the complex plane (seed 001 Figs. 2, 9): Re λ against frequency."""
    plt = pyplot()
    lam = np.ravel(lam)
    f = lam.imag / TWO_PI
    sel = (f >= band_hz[0]) & (f <= band_hz[1])
    bad = unstable(lam, growth_tol)
    fig, ax = plt.subplots(figsize=(8, 5))
    ax.plot(lam.real[sel & ~bad], f[sel & ~bad], ".", color="0.6", ms=2, label="stable")
    ax.plot(lam.real[sel & bad], f[sel & bad], ".", color="tab:red", ms=2, label="unstable")
    ax.axvline(0.0, color="k", lw=0.5)
    ax.set_xlabel("Re λ [1/s]")
    ax.set_ylabel("frequency [Hz]")
    ax.legend(loc="upper left")
    if title:
        ax.set_title(title)
    fig.tight_layout()
    save(fig, path)
    plt.close(fig)


def stability_maps(path: Path, mu: np.ndarray, E: np.ndarray, counts: np.ndarray, total: np.ndarray,
                   bands_hz: list[tuple[float, float]], E_label: str, title: str = "",
                   x_label: str = "sign(v) μ") -> None:
    """Number of unstable modes per band over the (sign(v)μ, E) plane, one panel per band and the
    total (seed 001 Figs. 17-19); counts[b] has shape (n_E, n_mu).  ``x_label``: another first axis
    than sign(v)μ (the map of a model given as matrices: two of its parameters)."""
    plt = pyplot()
    n = len(bands_hz) + 1
    cols = min(n, 4)
    rows = -(-n // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.4 * rows), squeeze=False)
    panels = [(f"{lo:.0f}-{hi:.0f} Hz", c) for (lo, hi), c in zip(bands_hz, counts)] + [("all bands", total)]
    for ax, (name, c) in zip(axes.ravel(), panels):
        im = ax.pcolormesh(mu, E, c, shading="nearest", cmap="magma_r", vmin=0, vmax=max(int(c.max()), 1))
        fig.colorbar(im, ax=ax, label="unstable modes")
        if x_label == "sign(v) μ":
            ax.axvline(0.0, color="k", lw=0.4)
        ax.set_title(name, fontsize=9)
        ax.set_xlabel(x_label)
        ax.set_ylabel(E_label)
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    save(fig, path)
    plt.close(fig)


def masa(path: Path, res, title: str = "", amplitude_label: str = "modal amplitude p") -> None:
    """Seed 000 Figs. 4–9 for one instability: every eigenvalue of the state matrix in the band
    against the amplitude (unstable ones coloured by their real part, stable ones grey), and the
    instability's own real part with its stationary amplitudes."""
    plt = pyplot()
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(7.5, 7.0), sharex=True, gridspec_kw={"height_ratios": [2, 1]},
                                 layout="constrained")
    p = np.repeat(res.amplitudes[:, None], res.eigenvalues.shape[1], axis=1)
    lam = res.eigenvalues
    ok = ~np.isnan(lam)
    unst = ok & unstable(np.nan_to_num(lam))  # the default growth_tol, as the result's own counts
    a1.scatter(p[ok & ~unst], lam[ok & ~unst].imag / TWO_PI / 1e3, s=2, c="0.75", lw=0)
    if unst.any():
        sc = a1.scatter(p[unst], lam[unst].imag / TWO_PI / 1e3, s=10, c=lam[unst].real, cmap="jet", lw=0)
        fig.colorbar(sc, ax=[a1, a2], label="Re λ [1/s]")
    a1.set_ylabel("frequency [kHz]")
    a1.set_title(title or f"MASA of the instability at {res.freq_hz:.0f} Hz")
    a2.plot(res.amplitudes, res.tracked.real, "k.-", ms=3)
    a2.axhline(0.0, color="0.5", lw=0.8)
    for s in res.stationary:
        a2.axvline(s, color="r", lw=0.8, ls="--")
    a2.set_ylabel(f"Re λ of the {res.freq_hz:.0f} Hz mode [1/s]")
    a2.set_xlabel(amplitude_label)
    save(fig, path)
    plt.close(fig)


def contact_status(path: Path, res, title: str = "", amplitude_label: str = "modal amplitude p") -> None:
    """Seed 000 Fig. 10: the status of every contact element against the amplitude: nothing for
    no contact, a dot for permanent contact, a red circle for impacts."""
    plt = pyplot()
    n_el = res.status.shape[1]
    fig, ax = plt.subplots(figsize=(7.5, max(3.0, min(9.0, 0.02 * n_el + 2))))
    P, E = np.meshgrid(res.amplitudes, np.arange(n_el), indexing="ij")
    perm, imp = res.status == 1, res.status == 2
    ax.scatter(P[perm], E[perm], s=1, c="k", lw=0)
    ax.scatter(P[imp], E[imp], s=6, facecolors="r", edgecolors="r", lw=0.3)
    ax.set_xlabel(amplitude_label)
    ax.set_ylabel("contact element")
    ax.set_title(title or f"contact status, instability at {res.freq_hz:.0f} Hz (dot: contact, red: impacts)")
    fig.tight_layout()
    save(fig, path)
    plt.close(fig)


def transient(path: Path, t: np.ndarray, x: np.ndarray, v: np.ndarray, extra: dict[str, np.ndarray] | None = None,
              title: str = "", label: str = "displacement [µm]", scale: float = 1e6) -> None:
    """Time history, spectrogram, phase portrait (last fifth) and extra histories of a transient."""


    plt = pyplot()
    extra = extra or {}
    fig, ax = plt.subplots(2, 2, figsize=(11, 7.5))
    ax[0, 0].plot(t * 1e3, x * scale, lw=0.4)
    ax[0, 0].set(xlabel="t [ms]", ylabel=label, title="time history")
    dt = float(np.mean(np.diff(t)))
    nper = min(1024, max(len(t) // 16, 16))
    from scipy.signal import spectrogram  # heavy: scipy.signal (0.6 s import; the transient plot only)

    fs, ts, S = spectrogram(x - np.mean(x), fs=1 / dt, nperseg=nper, noverlap=nper // 2)
    ax[0, 1].pcolormesh(ts * 1e3 + t[0] * 1e3, fs / 1e3, 10 * np.log10(S + S.max() * 1e-12), shading="auto")
    ax[0, 1].set(xlabel="t [ms]", ylabel="f [kHz]", title="spectrogram [dB]")
    tail = t >= t[0] + 0.8 * (t[-1] - t[0])
    ax[1, 0].plot(x[tail] * scale, v[tail] * scale, lw=0.4)
    ax[1, 0].set(xlabel=label, ylabel=label.replace("[", "rate [").replace("]", "/s]"),
                 title="phase portrait (last 20 %)")
    for name, y in extra.items():
        ax[1, 1].plot(t * 1e3, y, lw=0.5, label=name)
    if extra:
        ax[1, 1].legend(fontsize=7)
    ax[1, 1].set(xlabel="t [ms]", title="contact")
    fig.suptitle(title)
    fig.tight_layout()
    save(fig, path)
    plt.close(fig)


def dynamic_stability(path: Path, t: np.ndarray, lam: np.ndarray, band_hz, title: str = "") -> None:
    """Seed 002 Fig. 10: tangent-CEA frequencies and real parts against time along a cycle."""
    plt = pyplot()
    f = lam.imag / TWO_PI
    sel = (f >= band_hz[0]) & (f <= band_hz[1])
    tt = np.broadcast_to(t[:, None], lam.shape)
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    sc = ax[0].scatter(tt[sel] * 1e3, f[sel] / 1e3, c=lam.real[sel], s=4, cmap="coolwarm",
                       vmin=-np.abs(lam.real[sel]).max(), vmax=np.abs(lam.real[sel]).max())
    fig.colorbar(sc, ax=ax[0], label="Re λ [1/s]")
    ax[0].set(xlabel="t [ms]", ylabel="f [kHz]", title="frequency")
    ax[1].scatter(f[sel] / 1e3, lam.real[sel], c=tt[sel] * 1e3, s=4)
    ax[1].axhline(0, color="k", lw=0.5)
    ax[1].set(xlabel="f [kHz]", ylabel="Re λ [1/s]", title="frequency–damping (colour: t)")
    fig.suptitle(title)
    fig.tight_layout()
    save(fig, path)
    plt.close(fig)


def limit_cycle(path: Path, t: np.ndarray, x: np.ndarray, lc, svd_energy, best_mac: list[dict], t_shares,
                shares: np.ndarray | None, parts: list[str], cycles: list[dict], title: str = "") -> None:
    """Limit-cycle summary: envelope and saturation, SVD energy and MAC (seed 002 Figs. 8–9),
    component strain-energy shares along the cycle (Fig. 11), friction work per complex-mode
    cycle against α (§4.3)."""
    plt = pyplot()
    fig, ax = plt.subplots(2, 2, figsize=(11, 7.5))
    ax[0, 0].plot(t * 1e3, (x - np.mean(x)) * 1e6, lw=0.3, color="0.5")
    ax[0, 0].plot(t * 1e3, lc.envelope * 1e6, color="C3", lw=1, label="envelope")
    if lc.saturated:
        ax[0, 0].axvline(lc.t_saturation * 1e3, color="k", ls="--", lw=0.8, label="saturation")
    ax[0, 0].legend(fontsize=7)
    ax[0, 0].set(xlabel="t [ms]", ylabel="closure − mean [µm]",
                 title=f"{lc.frequency_hz:.0f} Hz, amplitude {lc.amplitude * 1e6:.3g} µm")
    k = np.arange(1, len(svd_energy) + 1)
    ax[0, 1].bar(k, svd_energy, color="C0")
    for b in best_mac:
        ax[0, 1].annotate(f"{b['freq_hz']:.0f} Hz\nplane {100 * b['plane_share']:.0f} %, MAC {b['mac']:.2f}",
                          (b["shape"], svd_energy[b["shape"] - 1]),
                          ha="center", va="bottom", fontsize=7)
    ax[0, 1].set(xlabel="SVD shape", ylabel="energy share", title="space–time SVD (strain-energy norm)")
    if shares is not None:
        ax[1, 0].stackplot(t_shares * 1e3, shares.T, labels=parts)
        ax[1, 0].legend(fontsize=6, loc="upper right")
    ax[1, 0].set(xlabel="t [ms]", ylabel="strain-energy share", title="components along the last cycle")
    if cycles:
        al = [c["alpha"] for c in cycles]
        ax[1, 1].loglog(al, np.abs([c["friction_work"] for c in cycles]), "o-")
    ax[1, 1].set(xlabel="α [× static closure]", ylabel="|friction work| per cycle [J]",
                 title="complex-mode cycles (seed 002 eq. 6)")
    fig.suptitle(title)
    fig.tight_layout()
    save(fig, path)
    plt.close(fig)


def pad_portraits(path: Path, runs: list[dict], pad, title: str = "") -> None:
    """Seed 004: phase portrait (tangential displacement, velocity) of the centre element and its
    sliding-speed history, one column per run, with the regime of each."""
    plt = pyplot()
    n = len(runs)
    fig, ax = plt.subplots(2, n, figsize=(max(3.0 * n, 6), 6), squeeze=False)
    for c, r in enumerate(runs):
        p = r["portrait"]
        ax[0, c].plot(p["x"] * 1e6, p["v"] * 1e3, lw=0.4)
        ax[0, c].set(xlabel="y [µm]", ylabel="ẏ [mm/s]" if c == 0 else "",
                     title=f"V = {r['speed'] * 1e3:g} mm/s\nv_s {r['v_s'] * 1e3:g}, v_d {r['v_d'] * 1e3:g} mm/s",
                     )
        ax[0, c].title.set_fontsize(8)
        ax[1, c].plot((p["t"] - p["t"][0]) * 1e3, p["w"] * 1e3, lw=0.4)
        ax[1, c].axhline(r["v_s"] * 1e3, color="C3", lw=0.6, ls="--")
        ax[1, c].axhline(r["v_d"] * 1e3, color="C2", lw=0.6, ls="--")
        ax[1, c].set(xlabel="t [ms]", ylabel="|w| [mm/s]" if c == 0 else "")
        ax[1, c].set_title(", ".join(sorted(set(r["regimes"]))), fontsize=8)
    fig.suptitle(f"segmented pad (μ_s {pad.mu_s}, μ_d {pad.mu_d}, F {pad.force:g} N) {title}")
    fig.tight_layout()
    save(fig, path)
    plt.close(fig)


def tornado(path: Path, record: dict, title: str = "") -> None:
    """Tornado plot of one mode's sensitivities (a record of results.json → sensitivity): the
    relative forms p·∂Re λ/∂p [1/s] and p·∂f/∂p [Hz], parameters sorted by |p·∂Re λ/∂p|."""
    plt = pyplot()
    fig, ax = plt.subplots(1, 2, figsize=(10, 0.5 * max(len(record["rel_d_real_part"]), 3) + 1.6))
    head = f"mode {record['index']}: {record['freq_hz']:.0f} Hz, Re λ = {record['real_part']:.3g} 1/s"
    if record["near_coalescence"]:
        for a in ax:
            a.text(0.5, 0.5, f"near a coalescence (κ_loc = {record['kappa_local']:.3g}):\n"
                   "the derivative is infinite", ha="center", va="center", transform=a.transAxes)
            a.set_axis_off()
    else:
        names = sorted(record["rel_d_real_part"], key=lambda p: abs(record["rel_d_real_part"][p]))
        y = np.arange(len(names))
        for a, key, label in ((ax[0], "rel_d_real_part", "p·∂Re λ/∂p [1/s]"),
                              (ax[1], "rel_d_freq_hz", "p·∂f/∂p [Hz]")):
            v = np.array([record[key][p] for p in names])
            a.barh(y, v, color=np.where(v > 0, "C3", "C0"))
            a.axvline(0, color="k", lw=0.8)
            a.set_yticks(y, names)
            a.set_xlabel(label)
    fig.suptitle(f"{head}  {title}", fontsize=9)
    fig.tight_layout()
    save(fig, path)
    plt.close(fig)


def robustness(path: Path, bands_hz, band_p, band_se, drivers: dict[str, dict], families: list[dict],
               title: str = "") -> None:
    """Robustness summary: instability probability per frequency band (± 2 standard errors), the
    drivers (Spearman ρ of each parameter with the largest growth rate and its 95 % interval), and
    the growth-rate histograms of the families most often unstable (``families``: label, growth)."""
    plt = pyplot()
    fig, ax = plt.subplots(1, 3, figsize=(15, 4.2))
    x = np.arange(len(bands_hz))
    ax[0].bar(x, band_p, yerr=2 * np.asarray(band_se), color="C3", capsize=3)
    ax[0].set_xticks(x, [f"{lo / 1e3:.1f}–{hi / 1e3:.1f}" for lo, hi in bands_hz], rotation=30, fontsize=7)
    ax[0].set(xlabel="band [kHz]", ylabel="P(≥ 1 unstable mode)", ylim=(0, 1.05), title="instability probability")
    names = list(drivers)
    rho = np.array([drivers[n]["rho"] for n in names])
    lo = rho - np.array([drivers[n]["ci95"][0] for n in names])
    hi = np.array([drivers[n]["ci95"][1] for n in names]) - rho
    ax[1].barh(np.arange(len(names)), rho, xerr=[lo, hi], color=np.where(rho > 0, "C3", "C0"), capsize=3)
    ax[1].set_yticks(np.arange(len(names)), names)
    ax[1].axvline(0, color="k", lw=0.8)
    ax[1].set(xlim=(-1, 1), xlabel="Spearman ρ with the largest growth rate", title="drivers (95 % interval)")
    for k, fam in enumerate(families):
        ax[2].hist(fam["growth"], bins=40, histtype="step", lw=1.2, color=f"C{k}", label=fam["label"])
    ax[2].axvline(0, color="k", lw=0.8)
    ax[2].set(xlabel="Re λ [1/s]", ylabel="samples", title="growth rate per mode family")
    if families:
        ax[2].legend(fontsize=7)
    fig.suptitle(title)
    fig.tight_layout()
    save(fig, path)
    plt.close(fig)


def coupling_matrix(path: Path, rows: list[dict], title: str = "", max_modes: int = 16) -> bool:
    """The participation [%] of the real modes (rows) in the unstable complex modes (columns; all modes
    when none is unstable), the real modes that reach 1 % in any of them; False when there is nothing."""
    modes = [r for r in rows if r["unstable"] and "coupling" in r] or [r for r in rows if "coupling" in r]
    modes = modes[:max_modes]
    if not modes:
        return False
    real = sorted({i for r in modes for i in r["coupling"]["real_modes"]})
    P = np.zeros((len(real), len(modes)))
    for j, r in enumerate(modes):
        for i, q in zip(r["coupling"]["real_modes"], r["coupling"]["percent"]):
            P[real.index(i), j] = q
    freq = {i: f for r in modes for i, f in zip(r["coupling"]["real_modes"], r["coupling"]["real_freqs_hz"])}
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(max(5.0, 2.4 + 0.75 * len(modes)), 1.6 + 0.32 * len(real)))
    im = ax.imshow(P, cmap="Reds", vmin=0, vmax=100, aspect="auto")
    for (i, j), q in np.ndenumerate(P):
        if q >= 1:
            ax.text(j, i, f"{q:.0f}", ha="center", va="center", fontsize=7, color="white" if q > 60 else "black")
    ax.set_xticks(range(len(modes)), [f"#{r['index']}\n{r['freq_hz']:.0f} Hz" for r in modes], fontsize=7)
    ax.set_yticks(range(len(real)), [f"{i}: {freq[i]:.0f} Hz" for i in real], fontsize=7)
    ax.set_xlabel("complex mode" + (" (unstable)" if modes[0]["unstable"] else ""))
    ax.set_ylabel("real mode of ½(K + Kᵀ)")
    fig.colorbar(im, ax=ax, label="participation [%]")
    ax.set_title(f"{title}\nmode coupling" if title else "mode coupling", fontsize=8)
    fig.tight_layout()
    save_figure_atomic(fig, path)
    plt.close(fig)
    return True


def part_participation(path: Path, rows: list[dict], title: str = "", max_modes: int = 16) -> bool:
    """Stacked bars: the strain-energy share of each part in each unstable mode (all modes when none is
    unstable); False when the modes carry no shares or the model has one part."""
    shared = [r for r in rows if "energy_shares" in r]
    modes = [r for r in shared if r["unstable"]] or shared
    modes = modes[:max_modes]
    if not modes or len(modes[0]["energy_shares"]) < 2:
        return False
    parts = list(modes[0]["energy_shares"])
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(max(5.0, 1.2 + 0.6 * len(modes)), 3.8))
    x = np.arange(len(modes))
    bottom = np.zeros(len(modes))
    for p in parts:
        h = np.array([100 * r["energy_shares"].get(p, 0.0) for r in modes])
        ax.bar(x, h, 0.7, bottom=bottom, label=p)
        bottom += h
    ax.set_xticks(x, [f"#{r['index']}\n{r['freq_hz']:.0f} Hz" for r in modes], fontsize=7)
    ax.set_ylabel("strain energy share [%]")
    ax.set_ylim(0, 100)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    ax.set_title(title or "part participation", fontsize=9)
    fig.tight_layout()
    save_figure_atomic(fig, path)
    plt.close(fig)
    return True


def erp_levels(path: Path, rows: list[dict], bands: list[dict], title: str = "") -> None:
    """ERP level [dB re 1 pW] of every complex mode over frequency (unstable ones red, sized by their
    growth rate), with the 1/3-octave band edges (1-16 kHz) as grid lines."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7.5, 4.0))
    f = np.array([r["freq_hz"] for r in rows])
    L = np.array([r["erp_db"] for r in rows])
    u = np.array([r["unstable"] for r in rows], bool)
    ax.scatter(f[~u], L[~u], s=14, c="0.5", label="stable")
    if u.any():
        g = np.array([r["real_part"] for r in rows])[u]
        ax.scatter(f[u], L[u], s=20 + 80 * g / g.max(), c="tab:red", label="unstable (size: Re λ)")
        for r in (r for r in rows if r["unstable"]):
            ax.annotate(f"#{r['index']}", (r["freq_hz"], r["erp_db"]), fontsize=7, xytext=(3, 3),
                        textcoords="offset points")
    for b in bands:
        ax.axvline(b["lower_hz"], color="0.85", lw=0.6, zorder=0)
    ax.set_xscale("log")
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("ERP [dB re 1 pW]")
    ax.legend(fontsize=8)
    ax.set_title(title or "equivalent radiated power", fontsize=9)
    fig.tight_layout()
    save_figure_atomic(fig, path)
    plt.close(fig)


def merging_pairs(path: Path, values: np.ndarray, lam: np.ndarray, unstable: np.ndarray,
                  events: list[tuple[float, float, dict]], xlabel: str, band_hz: tuple[float, float],
                  title: str = "") -> None:
    """Which real modes merge where: the tracked branches' frequencies over the swept parameter (grey,
    unstable points red) with each change of stability (value, frequency, coupling summary of
    :mod:`fem_squeal.reduced.mode_coupling`) marked and labelled by its real-mode pair."""
    plt = pyplot()
    f = lam.imag / TWO_PI
    keep = np.flatnonzero(np.any((f >= band_hz[0]) & (f <= band_hz[1]), axis=0))
    fig, ax = plt.subplots(figsize=(8, 5.5))
    for j in keep:
        ax.plot(values, f[:, j], "-", color="0.75", lw=0.7)
        u = unstable[:, j]
        if u.any():
            ax.plot(values[u], f[u, j], ".", color="tab:red", ms=3)
    marks, named = [], set()
    for v, fr, c in events:
        ax.plot([v], [fr], "o", mfc="none", mec="k", ms=6)
        key = (tuple(sorted(c["real_modes"][:2])), round(fr, -1))
        if key not in named:           # the same pair merging at ±μ: named once
            named.add(key)
            marks.append((v, fr, " + ".join(f"{i} ({q:.0f} %)" for i, q in zip(c["real_modes"][:2],
                                                                               c["percent"][:2]))))
    ax.set_ylim(*band_hz)
    _labels_apart(ax, marks)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("frequency [Hz]")
    ax.set_title((title + ": " if title else "") + "real modes merging at each change of stability", fontsize=9)
    fig.tight_layout()
    save_figure_atomic(fig, path)
    plt.close(fig)


def map_instabilities(path: Path, x: np.ndarray, y: np.ndarray, found: list[tuple[np.ndarray, str]], xlabel: str,
                      ylabel: str, title: str = "", top: int = 9) -> None:
    """Where each instability of a stability map lies, how fast it grows there and which real modes make
    it up: one panel for each of the first ``top`` of ``found`` = [(Re λ of shape (len(y), len(x)), NaN
    where stable; label)], its growth rate coloured over the (x, y) plane, its label as the panel's title.
    The CSV: one row per instability and unstable grid point."""
    plt = pyplot()
    n = max(min(len(found), top), 1)
    cols = min(n, 3)
    rows_ = -(-n // cols)
    fig, axes = plt.subplots(rows_, cols, figsize=(4.4 * cols, 3.5 * rows_), squeeze=False)
    X, Y = np.meshgrid(x, y)
    rows = []
    for k, (ax, (growth, label)) in enumerate(zip(axes.ravel(), found[:top])):
        im = ax.pcolormesh(x, y, np.ma.masked_invalid(growth), shading="nearest", cmap="magma_r",
                           vmin=0.0, vmax=float(np.nanmax(growth)))
        fig.colorbar(im, ax=ax, label="Re λ [1/s]")
        if xlabel == "sign(v) μ":
            ax.axvline(0.0, color="k", lw=0.4)
        ax.set_xlim(x.min(), x.max())
        ax.set_ylim(y.min(), y.max())
        f, _, pair = label.partition(": ")
        ax.set_title(f"{k + 1}: {f}" + (f"\n{pair}" if pair else ""), fontsize=8)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        ok = np.isfinite(growth)
        rows += [[k + 1, label, float(a), float(b), float(g)] for a, b, g in zip(X[ok], Y[ok], growth[ok])]
    for ax in axes.ravel()[min(len(found), top):]:
        ax.axis("off")
    fig.suptitle((title + ": " if title else "") + "instabilities of the map, fastest first, and their coupled "
                 "real modes", fontsize=9)
    fig.tight_layout()
    save(fig, path, (["instability", "label", xlabel, ylabel, "growth_rate"], columns_of(rows, 5)))
    plt.close(fig)


def noise_matrix(path: Path, noise: dict, frequencies: np.ndarray, growth: np.ndarray, condition: np.ndarray,
                 title: str = "") -> None:
    """The operating matrix as a dynamometer squeal summary (SAE J2521 style): occurrence of instability
    per 1/3-octave band [% of conditions], the unstable modes' frequencies per condition coloured by
    growth rate, and the occurrence against each condition variable that takes several values."""
    plt = pyplot()
    varying = [v for v, rows in noise["by_variable"].items() if len(rows) > 1]
    n = 2 + len(varying)
    cols = min(n, 3)
    rows = -(-n // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.6 * cols, 3.5 * rows), squeeze=False)
    ax = axes.ravel()
    b = noise["third_octave"]
    ax[0].bar(range(len(b)), [100.0 * r["occurrence"] for r in b], color="C3")
    ax[0].set_xticks(range(len(b)), [f"{r['band_hz'] / 1000:g}" for r in b], rotation=60, fontsize=7)
    ax[0].set_xlabel("1/3-octave band [kHz]")
    ax[0].set_ylabel("conditions with instability [%]")
    ax[0].set_ylim(0, 100)
    sc = ax[1].scatter(condition, np.asarray(frequencies) / 1000.0, c=growth, cmap="plasma", s=14)
    if len(condition):
        fig.colorbar(sc, ax=ax[1], label="growth rate Re λ [1/s]")
    ax[1].set_xlabel("condition")
    ax[1].set_ylabel("unstable mode [kHz]")
    ax[1].set_xlim(-0.5, noise["n_conditions"] - 0.5)
    for a, v in zip(ax[2:], varying):
        r = noise["by_variable"][v]
        a.bar(range(len(r)), [100.0 * x["occurrence"] for x in r], color="C0")
        a.set_xticks(range(len(r)), [x["value"] if isinstance(x["value"], str) else f"{x['value']:g}" for x in r])
        a.set_xlabel(v)
        a.set_ylabel("conditions with instability [%]")
        a.set_ylim(0, 100)
    for a in ax[n:]:
        a.axis("off")
    fig.suptitle(title or "operating matrix")
    fig.tight_layout()
    save(fig, path)
    plt.close(fig)
