"""Pictures of a design study (PNG, matplotlib's Agg backend), written into a folder it is given.

* ``band_NAME.png`` — a series output over the motion: the nominal curve above; below, the deviation from
  it: the linearized band ±1.96·σ_lin and the Monte-Carlo 2.5–97.5 percentiles and median (tolerance
  studies); or every variant's curve coloured by the first grid parameter (grid studies).
* ``hist_NAME.png`` — a scalar output's Monte-Carlo histogram with the linearized normal density
  N(nominal, σ_lin) over it (tolerance studies), or its values over the grid.
* ``map_NAME.png`` — a 2-D grid: the output over the two grid parameters (cells whose motion did not
  complete hatched grey); a Grashof class output as coloured classes with the minimum transmission angle
  drawn as contours over it when the study has that output.
* ``grid_NAME.png`` — a 1-D grid: the output against the parameter.

Angles are drawn in degrees (the tables keep radians).
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import numpy as np

MAX_CURVES = 200  # variants drawn in a grid study's series picture
MAX_BASES = 6  # base designs drawn in one band picture


def plot_study(res: Any, folder: str | Path) -> list[Path]:
    """Every picture the study's outputs call for, into ``folder``. Returns the paths written."""
    import matplotlib

    matplotlib.use("Agg")
    folder = Path(folder)
    out: list[Path] = []
    spec = res.spec
    grid_params = [p for p in spec.parameters if p.values is not None]
    tolerant = spec.samples is not None
    for o in spec.outputs:
        if o.stat == "series":
            out.append(_band(res, o, folder) if tolerant or not grid_params else _curves(res, o, grid_params, folder))
        elif o.stat in ("path", "class"):
            continue
        elif tolerant or len(grid_params) != 2:
            out.append(
                _hist(res, o, folder) if tolerant or len(grid_params) != 1 else _line(res, o, grid_params, folder)
            )
    if len(grid_params) == 2 and not tolerant:
        for o in spec.outputs:
            if o.stat in ("series", "path"):
                continue
            out.append(
                _class_map(res, o, grid_params, folder) if o.stat == "class" else _map(res, o, grid_params, folder)
            )
    return [p for p in out if p is not None]


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name)[:80]


def _unit(res: Any, name: str) -> tuple[float, str]:
    """(factor, unit) to draw an output in: radians become degrees."""
    from .studyfile import output_unit

    o = next(o for o in res.spec.outputs if name.startswith(o.name))
    u = output_unit(res.spec.mechanism, o)
    if u.startswith("rad"):
        return 180.0 / math.pi, "deg" + u[3:]
    return 1.0, u


def _save(fig: Any, path: Path) -> Path:
    import matplotlib.pyplot as plt

    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _band(res: Any, o: Any, folder: Path) -> Path | None:
    import matplotlib.pyplot as plt

    b = res.bands
    if not len(b):
        return None
    b = b[b["output"] == o.name]
    bases = sorted(b["base"].unique())[:MAX_BASES]
    k, unit = _unit(res, o.name)
    fig, axes = plt.subplots(2, 1, figsize=(8, 6.5), sharex=True, gridspec_kw={"height_ratios": [1, 1.3]})
    for i, base in enumerate(bases):
        rows = b[b["base"] == base]
        t, nom = rows["t"].to_numpy(), rows["nominal"].to_numpy() * k
        label = f" (grid point {base})" if len(bases) > 1 else ""
        axes[0].plot(t, nom, lw=1.6, color=f"C{i}", label=f"nominal{label}")
        if "linearized_sigma" in rows:
            s = 1.96 * rows["linearized_sigma"].to_numpy() * k
            axes[1].fill_between(t, -s, s, color=f"C{i}", alpha=0.25, lw=0, label=f"linearized ±1.96σ{label}")
        if "mc_p2.5" in rows:
            for q, ls in (("mc_p2.5", "--"), ("mc_p97.5", "--"), ("mc_p50", ":")):
                axes[1].plot(
                    t,
                    rows[q].to_numpy() * k - nom,
                    ls,
                    color=f"C{i}",
                    lw=1.2,
                    label=(
                        f"Monte-Carlo 2.5–97.5 %{label}"
                        if q == "mc_p2.5"
                        else f"Monte-Carlo median{label}"
                        if q == "mc_p50"
                        else None
                    ),
                )
    axes[0].set_ylabel(f"{o.quantity} [{unit}]")
    axes[1].set_ylabel(f"deviation from nominal [{unit}]")
    axes[1].set_xlabel("t [s]")
    for ax in axes:
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize=8)
    axes[0].set_title(f"{res.spec.mechanism.name}: {o.name} over the motion", fontsize=10)
    return _save(fig, folder / f"band_{_safe(o.name)}.png")


def _curves(res: Any, o: Any, grid_params: list, folder: Path) -> Path:
    import matplotlib.pyplot as plt

    table = res.table
    done = table[table["completed"]]
    k, unit = _unit(res, o.name)
    fig, ax = plt.subplots(figsize=(8, 5))
    first = grid_params[0].name
    vals = done[first].to_numpy()
    lo, hi = (vals.min(), vals.max()) if len(vals) else (0.0, 1.0)
    cmap = plt.get_cmap("viridis")
    step = max(1, math.ceil(len(done) / MAX_CURVES))
    for _, row in done.iloc[::step].iterrows():
        c = cmap((row[first] - lo) / (hi - lo) if hi > lo else 0.5)
        ax.plot(res.t, np.asarray(row[o.name]) * k, color=c, lw=0.8)
    sm = plt.cm.ScalarMappable(cmap=cmap, norm=plt.Normalize(lo, hi))
    fig.colorbar(sm, ax=ax, label=first)
    ax.set_xlabel("t [s]")
    ax.set_ylabel(f"{o.quantity} [{unit}]")
    ax.grid(True, alpha=0.3)
    ax.set_title(f"{res.spec.mechanism.name}: {o.name}, {len(done):,} completed variants", fontsize=10)
    return _save(fig, folder / f"band_{_safe(o.name)}.png")


def _hist(res: Any, o: Any, folder: Path) -> Path | None:
    import matplotlib.pyplot as plt

    y = res.table[o.name].dropna().to_numpy(dtype=float)
    if not len(y):
        return None
    k, unit = _unit(res, o.name)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    ax.hist(y * k, bins=min(80, max(10, int(math.sqrt(len(y))))), density=True, alpha=0.6, label="variants")
    s = res.summary
    if len(s):
        row = s[(s["output"] == o.name) & (s["grid"] == 0)].iloc[0]
        mu, sd = row["nominal"] * k, row["linearized_sigma"] * k
        if np.isfinite(mu) and np.isfinite(sd) and sd > 0:
            x = np.linspace(mu - 4 * sd, mu + 4 * sd, 400)
            ax.plot(
                x,
                np.exp(-0.5 * ((x - mu) / sd) ** 2) / (sd * math.sqrt(2 * math.pi)),
                "k-",
                lw=1.4,
                label=f"linearized N(nominal, σ = {sd:.3g})",
            )
            ax.axvline(mu, color="k", ls=":", lw=1)
        ax.set_title(
            f"{o.name}: Monte-Carlo σ = {row['mc_sigma'] * k:.3g} ± {row['mc_sigma_error'] * k:.2g} "
            f"({int(row['completed']):,} draws)",
            fontsize=10,
        )
    ax.set_xlabel(f"{o.name} [{unit}]")
    ax.set_ylabel("density")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    return _save(fig, folder / f"hist_{_safe(o.name)}.png")


def _line(res: Any, o: Any, grid_params: list, folder: Path) -> Path:
    import matplotlib.pyplot as plt

    t = res.table
    p = grid_params[0].name
    k, unit = _unit(res, o.name)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    ax.plot(t[p], t[o.name].to_numpy(dtype=float) * k, "o-", ms=3)
    stopped = t[~t["completed"]]
    for x in stopped[p]:
        ax.axvline(x, color="0.8", lw=3, zorder=0)
    ax.set_xlabel(p)
    ax.set_ylabel(f"{o.name} [{unit}]")
    ax.grid(True, alpha=0.3)
    ax.set_title(f"{res.spec.mechanism.name}: {o.name} (grey: motion not completed)", fontsize=10)
    return _save(fig, folder / f"grid_{_safe(o.name)}.png")


def _cells(res: Any, name: str, grid_params: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x values, y values, Z[y, x]) of an output over a 2-D grid (the first parameter slowest in the table)."""
    xs, ys = np.asarray(grid_params[0].values), np.asarray(grid_params[1].values)
    z = res.table[name].to_numpy()
    return xs, ys, z.reshape(len(xs), len(ys)).T


def _edges(v: np.ndarray) -> np.ndarray:
    if len(v) == 1:
        return np.array([v[0] - 0.5, v[0] + 0.5])
    mid = 0.5 * (v[1:] + v[:-1])
    return np.concatenate([[2 * v[0] - mid[0]], mid, [2 * v[-1] - mid[-1]]])


def _map(res: Any, o: Any, grid_params: list, folder: Path) -> Path:
    import matplotlib.pyplot as plt

    xs, ys, z = _cells(res, o.name, grid_params)
    k, unit = _unit(res, o.name)
    z = z.astype(float) * k
    fig, ax = plt.subplots(figsize=(7.5, 5.5))
    ax.pcolormesh(
        _edges(xs),
        _edges(ys),
        np.where(np.isfinite(z), np.nan, 1.0),
        cmap="Greys",
        vmin=0,
        vmax=4,
        hatch="//",
        shading="flat",
    )
    m = ax.pcolormesh(_edges(xs), _edges(ys), np.ma.masked_invalid(z), cmap="viridis", shading="flat")
    fig.colorbar(m, ax=ax, label=f"{o.name} [{unit}]")
    ax.set_xlabel(grid_params[0].name)
    ax.set_ylabel(grid_params[1].name)
    ax.set_title(f"{res.spec.mechanism.name}: {o.name} (grey: motion not completed)", fontsize=10)
    return _save(fig, folder / f"map_{_safe(o.name)}.png")


def _class_map(res: Any, o: Any, grid_params: list, folder: Path) -> Path:
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    xs, ys, z = _cells(res, o.name, grid_params)
    classes = sorted({str(c) for c in z.ravel() if c})
    index = {c: i for i, c in enumerate(classes)}
    zi = np.vectorize(lambda c: index.get(str(c), -1))(z).astype(float)
    colors = ["#4c72b0", "#55a868", "#c44e52", "#8172b2", "#ccb974", "#64b5cd", "#999999"]
    cmap = ListedColormap(colors[: max(len(classes), 1)])
    fig, ax = plt.subplots(figsize=(8, 5.8))
    ax.pcolormesh(
        _edges(xs),
        _edges(ys),
        np.ma.masked_less(zi, 0),
        cmap=cmap,
        vmin=-0.5,
        vmax=max(len(classes), 1) - 0.5,
        shading="flat",
    )
    handles = [Patch(color=colors[i % len(colors)], label=c) for i, c in enumerate(classes)]
    mu = next((m for m in res.spec.outputs if m.quantity.startswith("transmission_angle") and m.stat == "min"), None)
    if mu is not None and len(xs) > 1 and len(ys) > 1:
        _, _, zm = _cells(res, mu.name, grid_params)
        zm = zm.astype(float) * 180.0 / math.pi
        if np.isfinite(zm).sum() >= 4:
            cs = ax.contour(xs, ys, np.ma.masked_invalid(zm), colors="k", linewidths=0.9)
            ax.clabel(cs, fmt="%.0f°", fontsize=8)
            handles.append(Patch(facecolor="none", edgecolor="k", label=f"{mu.name} [deg] (completed motions)"))
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    ax.set_xlabel(grid_params[0].name)
    ax.set_ylabel(grid_params[1].name)
    ax.set_title(f"{res.spec.mechanism.name}: Grashof class", fontsize=10)
    return _save(fig, folder / f"map_{_safe(o.name)}.png")
