"""The person-to-person spread of the reach: the giver-dependent line and the per-person offsets
(``handover-data reach-spread PATH/whole_motions --out docs/calibration``).

The take distance (right shoulder to object at the detected transfer) is modelled as the
giver-dependent part plus a per-person offset (:mod:`handover_env.person.reach_offset`).
:func:`run_reach_spread`

1. analyses every recording as ``transfer-stats`` does
   (:func:`~handover_eval.calibration.report.analyse_folder`) and splits them into Table I's
   halves (:func:`~handover_eval.calibration.report.assign_halves`: folds 0-4 calibrate, 5-9 are
   held out);
2. on the **calibration half only** fits the giver-dependent part: the least-squares line of the
   reach (``object_shoulder_transfer``) on the closest approach of the shoulder's path to the
   object held where it was at the reach onset (``path_closest_onset``), as
   :func:`~handover_eval.calibration.decisions.reach_fit` does, and compares it with the
   person's :data:`~handover_env.person.receiver_rules.TAKE_INTERCEPT` / ``TAKE_CLOSEST``;
3. takes the line's residuals on the calibration half as the per-person offsets
   (:func:`handover_env.person.reach_offset.reach_offset`) and describes them: mean, SD, a robust
   SD (1.4826 MAD), skewness and excess kurtosis with their standard errors, Shapiro-Wilk, and
   quantiles; the **distribution** is chosen by :func:`choose_distribution` (normal unless the
   skewness or the excess kurtosis lies beyond two standard errors of a normal's, then the
   empirical quantile function);
4. on the **held-out half** reports how well the giver-dependent part predicts the recorded
   reach (Pearson r, RMSE, the SD of its predictions against the recorded SD) and what the line
   plus an offset drawn from the calibration half's distribution spreads
   (sqrt(var(line) + SD_offset^2)), for ID, OOD and pooled;
5. writes ``reach_spread.json``, ``reach_spread.md`` and ``reach_spread.png`` through
   :mod:`handover_eval.reporting`.

Only statistics over recordings leave this module (quantiles are interpolated between
recordings, the extremes are not written); no per-recording value is stored.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import stats

from handover_env.person.reach_offset import reach_offset
from handover_env.person.receiver_rules import TAKE_CLOSEST, TAKE_INTERCEPT
from handover_eval.calibration.report import (
    DEFAULT_CALIBRATION_FOLDS,
    DEFAULT_FOLDS,
    DEFAULT_SEED,
    RecordingResult,
    analyse_folder,
    assign_halves,
    write_json,
)
from handover_eval.reporting import markdown_table, write_png, write_text

JSON_NAME, MD_NAME, FIGURE_NAME = "reach_spread.json", "reach_spread.md", "reach_spread.png"
COMMAND = "handover-data reach-spread PATH/whole_motions --out docs/calibration"
#: The reach statistic and the giver-dependent part's input (measures of
#: :func:`~handover_eval.calibration.measures.analyse_recording`).
RESPONSE, PREDICTOR = "object_shoulder_transfer", "path_closest_onset"
#: Probabilities of the residual quantiles written (the extremes are one recording's own value,
#: so the quantile function stops at 0.5 % and 99.5 %).
PROBABILITIES = (0.005, 0.01, 0.025, 0.05, 0.10, 0.25, 0.50, 0.75, 0.90, 0.95, 0.975, 0.99, 0.995)
#: The offset distribution's numbers are written to 0.1 mm (the person copies them).
DIGITS = 4
#: A normal is chosen when |skewness| and |excess kurtosis| lie within this many standard
#: errors of a normal sample's (sqrt(6/n), sqrt(24/n)).
SHAPE_SE = 2.0
#: Closest-approach bins of the figure's held-out panel, m; a bin is drawn with >= MIN_BIN.
BIN_EDGES = (0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 1.0)
MIN_BIN = 10
GROUPS = ("id", "ood", "all")


@dataclass(frozen=True)
class ReachRow:
    """One recording's reach and closest approach, in memory only (never written)."""

    calibration: bool
    is_ood: bool
    reach: float
    closest: float


def reach_rows(results: list[RecordingResult]) -> list[ReachRow]:
    """The recordings with a transfer and a reach onset (both measures finite), halves set."""
    rows = []
    for r in results:
        y, x = r.analysis.measures[RESPONSE], r.analysis.measures[PREDICTOR]
        if math.isfinite(y) and math.isfinite(x):
            rows.append(ReachRow(r.calibration, r.is_ood, float(y), float(x)))
    return rows


def _select(rows: list[ReachRow], calibration: bool, group: str) -> list[ReachRow]:
    return [r for r in rows if r.calibration == calibration
            and (group == "all" or r.is_ood == (group == "ood"))]


def _xy(rows: list[ReachRow]) -> tuple[np.ndarray, np.ndarray]:
    return (np.array([r.closest for r in rows], dtype=np.float64),
            np.array([r.reach for r in rows], dtype=np.float64))


def fit_line(x: np.ndarray, y: np.ndarray) -> dict[str, float]:
    """Least-squares line ``y = a + b x`` with its Pearson r and n.

    Raises:
        ValueError: fewer than 3 points or no spread in x.
    """
    if x.size < 3 or float(np.std(x)) == 0.0:
        raise ValueError(f"cannot fit the reach line on {x.size} recording(s) with a transfer and "
                         "a reach onset (need >= 3 with different closest approaches)")
    b, a = np.polyfit(x, y, 1)
    r = float(np.corrcoef(x, y)[0, 1]) if float(np.std(y)) > 0 else math.nan
    return {"n": int(x.size), "intercept": float(a), "slope": float(b), "r": r}


def residual_summary(res: np.ndarray) -> dict:
    """Mean, SD, robust SD, shape (skewness, excess kurtosis, standard errors), Shapiro-Wilk and
    quantiles (:data:`PROBABILITIES`) of the residuals; mean, SD and quantiles to :data:`DIGITS`
    decimals."""
    n = int(res.size)
    out: dict = {
        "n": n,
        "mean": round(float(res.mean()), DIGITS) + 0.0,
        "sd": round(float(res.std(ddof=1)), DIGITS),
        "robust_sd": float(1.4826 * np.median(np.abs(res - np.median(res)))),
        "skewness": float(stats.skew(res)),
        "excess_kurtosis": float(stats.kurtosis(res)),
        "skewness_se": math.sqrt(6.0 / n),
        "kurtosis_se": math.sqrt(24.0 / n),
        "quantiles": [[p, round(float(np.quantile(res, p)), DIGITS) + 0.0] for p in PROBABILITIES],
    }
    out["shapiro_p"] = float(stats.shapiro(res).pvalue) if n >= 3 else math.nan
    z = stats.norm.ppf(PROBABILITIES)
    out["normal_quantiles"] = [[p, out["mean"] + out["sd"] * float(q)]
                               for p, q in zip(PROBABILITIES, z, strict=True)]
    return out


def choose_distribution(summary: dict) -> tuple[str, str]:
    """``("normal" | "quantiles", why)`` for residuals described by :func:`residual_summary`."""
    skew, kurt = summary["skewness"], summary["excess_kurtosis"]
    s_lim, k_lim = SHAPE_SE * summary["skewness_se"], SHAPE_SE * summary["kurtosis_se"]
    if abs(skew) <= s_lim and abs(kurt) <= k_lim:
        return "normal", (
            f"skewness {skew:+.2f} within +-{s_lim:.2f} and excess kurtosis {kurt:+.2f} within "
            f"+-{k_lim:.2f} ({SHAPE_SE:g} standard errors of a normal sample's): a normal "
            "with the residuals' mean and SD")
    judged = [f"skewness {skew:+.2f} {'beyond' if abs(skew) > s_lim else 'within'} "
              f"+-{s_lim:.2f}",
              f"excess kurtosis {kurt:+.2f} {'beyond' if abs(kurt) > k_lim else 'within'} "
              f"+-{k_lim:.2f}"]
    return "quantiles", (
        f"{' and '.join(judged)} ({SHAPE_SE:g} standard errors of a normal sample's): not a "
        "normal; the residuals' own quantile function (piecewise linear)")


def predict_summary(x: np.ndarray, y: np.ndarray, line: dict, offset_sd: float) -> dict:
    """How the line predicts ``y`` from ``x`` (r, RMSE, SDs) and the spread of line + offset."""
    n = int(x.size)
    if n < 3:
        return {"n": n}
    pred = line["intercept"] + line["slope"] * x
    res = y - pred
    sd_pred = float(np.std(pred, ddof=1))
    return {
        "n": n,
        "r": float(np.corrcoef(pred, y)[0, 1]),
        "rmse": float(np.sqrt(np.mean(res**2))),
        "mean_residual": float(res.mean()),
        "residual_sd": float(res.std(ddof=1)),
        "recorded_sd": float(np.std(y, ddof=1)),
        "recorded_median": float(np.median(y)),
        "line_sd": sd_pred,
        "line_plus_offset_sd": float(math.sqrt(sd_pred**2 + offset_sd**2)),
        "line_median": float(np.median(pred)),
    }


def summarise(
    rows: list[ReachRow],
    *,
    source: str = "",
    folds: int = DEFAULT_FOLDS,
    seed: int = DEFAULT_SEED,
    calibration_folds: int = DEFAULT_CALIBRATION_FOLDS,
    recordings: int = 0,
) -> dict:
    """The JSON-able summary of :func:`run_reach_spread` (module docstring)."""
    x_c, y_c = _xy(_select(rows, True, "all"))
    line = fit_line(x_c, y_c)
    offsets = np.array([reach_offset(float(y), float(x), line["intercept"], line["slope"])
                        for x, y in zip(x_c, y_c, strict=True)])
    res = residual_summary(offsets)
    kind, why = choose_distribution(res)
    by_kind = {}
    for group in ("id", "ood"):
        xg, yg = _xy(_select(rows, True, group))
        off = yg - (line["intercept"] + line["slope"] * xg)
        by_kind[group] = {"n": int(off.size),
                          "mean": float(off.mean()) if off.size else None,
                          "sd": float(off.std(ddof=1)) if off.size > 1 else None}
    held = {g: predict_summary(*_xy(_select(rows, False, g)), line, res["sd"]) for g in GROUPS}
    calib = {g: predict_summary(*_xy(_select(rows, True, g)), line, res["sd"]) for g in GROUPS}
    return {
        "command": COMMAND,
        "source": source,
        "recordings": recordings,
        "split": {
            "method": "Table I stratified folds (handover_env.data.dataset.stratified_fold_ids) "
                      "over the files in list_public_files order",
            "folds": folds, "seed": seed,
            "calibration_folds": list(range(calibration_folds)),
            "held_out_folds": list(range(calibration_folds, folds)),
        },
        "response": RESPONSE,
        "predictor": PREDICTOR,
        "line": {
            **line,
            "person_intercept": TAKE_INTERCEPT,
            "person_slope": TAKE_CLOSEST,
            "matches_person": bool(round(line["intercept"], 3) == TAKE_INTERCEPT
                                   and round(line["slope"], 3) == TAKE_CLOSEST),
        },
        "offset": {**res, "distribution": kind, "why": why, "by_kind": by_kind},
        "calibration": calib,
        "held_out": held,
    }


def _f(v: float | None, digits: int = 3) -> str:
    return "–" if v is None or (isinstance(v, float) and not math.isfinite(v)) else \
        f"{v:.{digits}f}"


def markdown(summary: dict, figure: str | None) -> str:
    """The page ``reach_spread.md``."""
    line, off = summary["line"], summary["offset"]
    split = summary["split"]
    sizes = {h: summary[h]["all"]["n"] for h in ("calibration", "held_out")}
    text = (
        "# The reach: what the giver explains and what is the person's own\n\n"
        f"Generated by `{summary['command']}` from `{summary['source']}` "
        f"({summary['recordings']} recordings; {sizes['calibration']} calibration and "
        f"{sizes['held_out']} held-out recordings with a transfer and a reach onset). Code: "
        "`handover_eval/calibration/reach_spread.py` (this page), "
        "`handover_env/person/reach_offset.py` (the offset of one recording, the distribution the "
        "person draws from). Statistics over recordings only.\n\n"
        "The reach statistic is the right shoulder's distance from the object at the detected "
        "transfer (`object_shoulder_transfer`, the env's `reach_distance`; "
        "`receiver_calibration.md`). It is modelled as\n\n"
        "    take = a + b * closest + offset\n\n"
        "* **modelled, the giver's part**: `a + b * closest`, where `closest` "
        "(`path_closest_onset`) is the nearest the right shoulder's path from the reach onset on "
        "comes to the object held where it was at the onset (how far from the person's path "
        "the giver holds it);\n"
        "* **the person's own offset**: everything else, i.e. how far this person likes to "
        "reach, plus the tracker's and the detector's error on this statistic. Scripted walkers "
        "draw it from the distribution below with their seed; a replayed recording carries its "
        "own (`recording_reach_offset`: the recorded reach minus the line's prediction from the "
        "recorded approach), so a replayed person is that person.\n\n"
        "Under giver replay the replayed person's reach therefore contains the recorded reach's "
        "residual by construction: the per-recording correlation of simulated and recorded reach "
        "is no longer a test of the model. The test of the model is how well its giver-dependent "
        "part predicts the held-out half (below).\n\n"
        f"Split: Table I's stratified folds (seed {split['seed']}): folds "
        f"{split['calibration_folds'][0]}-{split['calibration_folds'][-1]} calibrate, "
        f"{split['held_out_folds'][0]}-{split['held_out_folds'][-1]} are held out. The line and "
        "the offsets come from the calibration half only.\n\n"
        "## The giver's part (calibration half)\n\n"
        f"Least squares on n = {line['n']}: reach = {line['intercept']:.3f} + "
        f"{line['slope']:.3f} x closest (r = {line['r']:.2f}). The person's "
        f"`receiver_rules.TAKE_INTERCEPT` / `TAKE_CLOSEST` = {line['person_intercept']:.3f} / "
        f"{line['person_slope']:.3f}: "
        + ("the same line." if line["matches_person"] else "**not** this line.")
        + "\n\n## The per-person offset (calibration half residuals)\n\n"
    )
    text += markdown_table(
        ("n", "mean (m)", "SD (m)", "robust SD, 1.4826 MAD (m)", "skewness (SE)",
         "excess kurtosis (SE)", "Shapiro-Wilk p"),
        [(off["n"], _f(off["mean"]), _f(off["sd"]), _f(off["robust_sd"]),
          f"{off['skewness']:+.2f} ({off['skewness_se']:.2f})",
          f"{off['excess_kurtosis']:+.2f} ({off['kurtosis_se']:.2f})",
          _f(off["shapiro_p"], 3))],
    )
    text += "\n" + markdown_table(
        ("by walk", "n", "mean (m)", "SD (m)"),
        [(g.upper(), v["n"], _f(v["mean"]), _f(v["sd"])) for g, v in off["by_kind"].items()],
    )
    text += "\nQuantiles of the residuals against a normal with their mean and SD:\n\n"
    text += markdown_table(
        ("probability", *(f"{100 * p:g} %" for p, _ in off["quantiles"])),
        [("residual (m)", *(_f(v) for _, v in off["quantiles"])),
         ("normal (m)", *(_f(v) for _, v in off["normal_quantiles"]))],
    )
    draw = ("one standard-normal draw scaled by the SD" if off["distribution"] == "normal" else
            "one uniform draw through the piecewise-linear quantile function above (0.5 .. "
            "99.5 %; a draw beyond takes the end value)")
    text += (
        f"\n**Distribution: {off['distribution']}.** {off['why']}. The person draws an offset "
        f"with `handover_env.person.reach_offset.REACH_OFFSET.draw(rng)`: {draw}. The offsets "
        "are pooled over ID and OOD walks (a person's liking for a reach does not depend on "
        "how they walk; the two SDs above agree).\n\n"
        "## How well the giver's part predicts (held-out half)\n\n"
        "The line fitted on the calibration half, applied to the held-out half's recorded "
        "approach. `line + offset SD` = sqrt(var(line) + SD_offset^2), the spread of the modelled "
        "reach when each person draws an offset from the calibration half's distribution, to be "
        "compared with the recorded SD.\n\n"
    )
    rows = []
    for half in ("held_out", "calibration"):
        for g in GROUPS:
            v = summary[half][g]
            if v.get("n", 0) < 3:
                rows.append((half.replace("_", "-"), g.upper(), v.get("n", 0), *("–",) * 8))
                continue
            rows.append((half.replace("_", "-"), "pooled" if g == "all" else g.upper(), v["n"],
                         _f(v["r"], 2), _f(v["rmse"]), _f(v["recorded_sd"]), _f(v["line_sd"]),
                         _f(v["line_plus_offset_sd"]), _f(v["residual_sd"]),
                         _f(v["recorded_median"]), _f(v["line_median"])))
    text += markdown_table(
        ("half", "walks", "n", "r", "RMSE (m)", "recorded SD (m)", "line SD (m)",
         "line + offset SD (m)", "residual SD (m)", "recorded median (m)", "line median (m)"),
        rows,
    )
    if figure:
        text += (
            f"\n![reach spread](./{figure})\n\nLeft: the calibration half's residuals "
            "(histogram) and a normal of the same mean and SD. Middle: their quantiles (0.5 .. "
            "99.5 %) against that normal's. Right: held-out half, the recorded reach (median "
            f"and 25-75 % per bin of the closest approach, bins of >= {MIN_BIN} recordings) and "
            "the line.\n"
        )
    return text


def write_figure(rows: list[ReachRow], summary: dict, path: str | os.PathLike) -> Path:
    """The three panels of the page (distributions only, never a single recording)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    line, off = summary["line"], summary["offset"]
    x_c, y_c = _xy(_select(rows, True, "all"))
    res = y_c - (line["intercept"] + line["slope"] * x_c)
    fig, axes = plt.subplots(1, 3, figsize=(13, 4))
    ax = axes[0]
    ax.hist(res, bins=30, density=True, color="tab:blue", alpha=0.6, label="residuals")
    grid = np.linspace(res.min(), res.max(), 200)
    ax.plot(grid, stats.norm.pdf(grid, off["mean"], off["sd"]), "k-",
            label=f"normal of the same mean and SD ({off['sd']:.3f} m)")
    ax.set_xlabel("offset = reach - line, m")
    ax.set_ylabel("density")
    ax.legend(fontsize=8)
    ax = axes[1]
    emp = np.array([v for _, v in off["quantiles"]])
    nor = np.array([v for _, v in off["normal_quantiles"]])
    ax.plot(nor, emp, "o-", color="tab:blue")
    lim = [min(nor.min(), emp.min()), max(nor.max(), emp.max())]
    ax.plot(lim, lim, "k--", lw=1)
    ax.set_xlabel("normal quantile, m")
    ax.set_ylabel("residual quantile, m")
    ax.set_title("0.5 .. 99.5 %", fontsize=9)
    ax = axes[2]
    x_h, y_h = _xy(_select(rows, False, "all"))
    centres, q = [], []
    for lo, hi in zip(BIN_EDGES[:-1], BIN_EDGES[1:], strict=True):
        inside = (x_h >= lo) & (x_h < hi)
        if inside.sum() >= MIN_BIN:
            centres.append(0.5 * (lo + hi))
            q.append(np.percentile(y_h[inside], [25, 50, 75]))
    if centres:
        qa = np.array(q)
        ax.fill_between(centres, qa[:, 0], qa[:, 2], color="tab:orange", alpha=0.3, lw=0,
                        label="recorded 25-75 %")
        ax.plot(centres, qa[:, 1], "o-", color="tab:orange", label="recorded median")
    xs = np.array([BIN_EDGES[0], BIN_EDGES[-1]])
    ax.plot(xs, line["intercept"] + line["slope"] * xs, "k-", label="line (calibration)")
    ax.set_xlabel("closest approach of the shoulder's path, m")
    ax.set_ylabel("reach (shoulder-object at transfer), m")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return write_png(fig, path, dpi=110)


def run_reach_spread(
    folder: str | os.PathLike,
    out_dir: str | os.PathLike,
    *,
    folds: int = DEFAULT_FOLDS,
    seed: int = DEFAULT_SEED,
    calibration_folds: int = DEFAULT_CALIBRATION_FOLDS,
    skip_bad: bool = False,
    figures: bool = True,
    progress: bool = True,
) -> tuple[dict, list[Path]]:
    """Analyse ``folder``, split it, write the JSON, the page and the figure into ``out_dir``.

    Returns:
        ``(summary, written paths)``.
    """
    results, _ = analyse_folder(folder, skip_bad=skip_bad, progress=progress)
    assign_halves(results, folds, seed, calibration_folds)
    rows = reach_rows(results)
    summary = summarise(rows, source=Path(folder).name, folds=folds, seed=seed,
                        calibration_folds=calibration_folds, recordings=len(results))
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = [write_json(summary, out / JSON_NAME)]
    if figures:
        written.append(write_figure(rows, summary, out / FIGURE_NAME))
    written.append(write_text(markdown(summary, FIGURE_NAME if figures else None),
                              out / MD_NAME))
    return summary, written


__all__ = [
    "ReachRow",
    "choose_distribution",
    "fit_line",
    "markdown",
    "predict_summary",
    "reach_rows",
    "residual_summary",
    "run_reach_spread",
    "summarise",
]
