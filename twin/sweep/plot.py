"""Pictures of a sweep (`twin sweep --plot`, `twin sweep plot DIR`, `twin sweep compare --plot`):
one PNG with each scenario over the two varied keys that matter most (ok as dots coloured by
placement error, failed as red crosses; for a comparison the flips ringed), and the distribution
of the placement error. matplotlib is an optional extra (`pip install 'twin[plot]'`), imported
only here and only when a picture is asked for."""

from __future__ import annotations

import numpy as np
import pyarrow as pa

from twin.model.errors import ConfigError
from twin.record.outputs import atomic_path
from twin.sweep.paired import Paired, Side


def pyplot():
    """matplotlib.pyplot on the Agg backend (no display needed); ConfigError (exit 2) when
    matplotlib is not installed."""
    try:
        import matplotlib
    except ImportError:
        raise ConfigError("--plot needs matplotlib, which is not installed; expected "
                          "`pip install 'twin[plot]'` (or matplotlib>=3.8)") from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def key_scores(side: Side) -> dict[str, float]:
    """How much each numeric varied key matters, 0..1: the larger of how well it separates ok
    from failed scenarios (|2 AUC - 1| of its ranks) and how it orders the placement error
    (|Spearman's rho|). Keys with one value, or not numbers, are left out."""
    scores = {}
    for key in side.keys:
        column = side.table.column(key)
        if not (pa.types.is_integer(column.type) or pa.types.is_floating(column.type)):
            continue
        x = column.to_numpy(zero_copy_only=False).astype(float)
        if np.unique(x[~np.isnan(x)]).size < 2:
            continue
        ranks = _ranks(x)
        score = 0.0
        failed = ~side.ok
        if failed.any() and side.ok.any():
            auc = (ranks[side.ok].mean() - ranks[failed].mean()) / len(x) * 2
            score = abs(auc)
        placed = ~np.isnan(side.placement_mm) & ~np.isnan(x)
        if placed.sum() > 2:
            rho = np.corrcoef(_ranks(x[placed]), _ranks(side.placement_mm[placed]))[0, 1]
            if np.isfinite(rho):
                score = max(score, abs(float(rho)))
        scores[key] = score
    return dict(sorted(scores.items(), key=lambda kv: -kv[1]))


def _ranks(x: np.ndarray) -> np.ndarray:
    order = np.argsort(x, kind="stable")
    ranks = np.empty(len(x))
    ranks[order] = np.arange(len(x))
    return ranks


def plot_sweep(side: Side, out_png: str, title: str, comparison: Paired | None = None,
               reference: Side | None = None) -> list[str]:
    """Write the PNG; returns the keys on its axes. With comparison (new = side), the flips are
    ringed and the reference's placement error is drawn beside the new one's."""
    plt = pyplot()
    keys = list(key_scores(side))[:2]
    panels = 3 if comparison is not None else 2
    fig, axes = plt.subplots(1, panels, figsize=(6.2 * panels, 5.2), constrained_layout=True)
    _scatter(axes[0], side, keys, comparison)
    _histogram(axes[1], side, reference)
    if comparison is not None:
        _differences(axes[2], comparison)
    fig.suptitle(title)
    try:
        with atomic_path(out_png) as tmp:
            fig.savefig(tmp, dpi=110, format="png")
    finally:
        plt.close(fig)
    return keys


def _axis(side: Side, keys: list[str], k: int) -> tuple[np.ndarray, str]:
    if k < len(keys):
        return side.table.column(keys[k]).to_numpy(zero_copy_only=False).astype(float), keys[k]
    if k == 0:
        return side.scenario.astype(float), "scenario"
    return side.placement_mm, "placement error (mm)"


def _scatter(ax, side: Side, keys: list[str], comparison: Paired | None) -> None:
    x, xlabel = _axis(side, keys, 0)
    y, ylabel = _axis(side, keys, 1)
    placed_ok = side.ok & ~np.isnan(side.placement_mm)
    dots = ax.scatter(x[placed_ok], y[placed_ok], c=side.placement_mm[placed_ok], cmap="viridis",
                      s=22, label=f"ok ({int(side.ok.sum())})")
    if placed_ok.any():
        ax.figure.colorbar(dots, ax=ax, label="placement error (mm)")
    failed = ~side.ok
    ax.scatter(x[failed], y[failed], marker="x", color="tab:red", s=36, linewidths=1.6,
               label=f"failed ({int(failed.sum())})")
    if comparison is not None and comparison.common is not None:
        where = np.searchsorted(side.scenario, comparison.common)
        for kind, marker, colour, text in ((-1, "o", "tab:red", "ok -> failed"),
                                           (1, "s", "tab:green", "failed -> ok")):
            sel = where[comparison.flip_kind == kind]
            if sel.size:
                ax.scatter(x[sel], y[sel], marker=marker, s=170, facecolors="none",
                           edgecolors=colour, linewidths=2.0, label=f"{text} ({sel.size})")
                for i in sel[:12]:  # the scenario numbers, for `twin sweep ... --only N`
                    ax.annotate(str(side.scenario[i]), (x[i], y[i]), xytext=(6, 6),
                                textcoords="offset points", fontsize=8, color=colour)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title("each scenario: where it fails")
    ax.legend(loc="best", fontsize=8)


def _histogram(ax, side: Side, reference: Side | None) -> None:
    values = side.placement_mm[~np.isnan(side.placement_mm)]
    others = ([] if reference is None
              else [reference.placement_mm[~np.isnan(reference.placement_mm)]])
    everything = np.concatenate([values, *others]) if values.size or others else values
    bins = np.histogram_bin_edges(everything, bins=30) if everything.size else 10
    if reference is not None:
        ax.hist(others[0], bins=bins, histtype="step", linewidth=1.8, color="0.45",
                label=f"reference ({others[0].size})")
    ax.hist(values, bins=bins, alpha=0.75, color="tab:blue",
            label=f"{'new' if reference is not None else 'placed'} ({values.size})")
    if values.size:
        for q, style in ((50, "--"), (95, ":")):
            v = float(np.percentile(values, q))
            ax.axvline(v, color="k", linestyle=style, linewidth=1, label=f"p{q} {v:.1f} mm")
    ax.set_xlabel("placement error (mm)")
    ax.set_ylabel("scenarios")
    ax.set_title("placement error")
    ax.legend(fontsize=8)


def _differences(ax, p: Paired) -> None:
    moved = p.moved[~np.isnan(p.moved)] if p.moved is not None else np.array([])
    if moved.size:
        ax.hist(moved, bins=30, color="tab:purple", alpha=0.8)
    if p.shift is not None:
        med, lo, hi = p.shift
        ax.axvspan(lo, hi, color="tab:orange", alpha=0.25, label=f"95 % [{lo:+.2f}, {hi:+.2f}]")
        ax.axvline(med, color="tab:orange", linewidth=2, label=f"median {med:+.3f} mm")
        ax.legend(fontsize=8)
    ax.set_xlabel("placement error, new - reference (mm)")
    ax.set_ylabel("scenarios placed in both")
    ax.set_title(f"paired shift; flips: {p.worse} ok->failed, {p.better} failed->ok")
