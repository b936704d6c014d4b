"""`mocap compare`: every intrinsic initialiser on the same features and matches, side by side.

Each method runs in its own branch of the workspace (``WS/compare/<method>/``: the images are
shared, the database is a copy made after matching), so methods cannot influence each other and
each branch is an ordinary workspace that COLMAP or `mocap view` can open. Outputs:

    WS/compare/comparison.json   the figures (format below)
    WS/compare/report.md         the same as Markdown, with the per-pair Kruppa table
    WS/compare/pairs.png         per-pair Kruppa focal, the fused value and the truth
    WS/compare/errors.png        relative focal error by method
    WS/compare/principal_points.png  each method's principal point against the truth
    WS/logs/compare.rrd          the same figures in Rerun
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from recon.errors import UserError
from recon.evaluation.truth import GroundTruth, load_ground_truth
from recon.sfm.images import exif_focal_px
from recon.sfm.pipeline import (
    SfMConfig,
    extract_features,
    initialise_intrinsics,
    map_sparse,
    match_features,
)
from recon.workspace import Workspace, atomic_output, write_json_atomic


@dataclass(frozen=True)
class Method:
    name: str
    plugin: str
    options: tuple[str, ...] = ()


METHODS: tuple[Method, ...] = (
    Method("kruppa", "kruppa", ("refine=false",)),
    Method("kruppa-pp", "kruppa-pp", ("refine=false",)),
    Method("kruppa-pp-epipolar", "kruppa-pp", ("refine=false", "principal_point=epipolar")),
    Method("kruppa-per-image", "kruppa", ("refine=false", "camera_mode=per-image")),
    Method("kruppa+ba", "kruppa", ("refine=true",)),
    Method("colmap-default+ba", "colmap-default"),
    Method("view-graph", "view-graph", ("refine=false",)),
    Method("view-graph+ba", "view-graph", ("refine=true",)),
    Method("exif", "exif", ("refine=false",)),
    Method("exif+ba", "exif", ("refine=true",)),
)


@dataclass(frozen=True, kw_only=True)
class CompareConfig:
    gt: Path | None = field(
        default=None,
        metadata={
            "help": "ground truth: Middlebury *_par.txt, folder of Strecha *.camera files, "
            "K.txt, COLMAP model folder, or mocap-cameras-v1 JSON"
        },
    )
    json: Path | None = field(
        default=None, metadata={"help": "also write the comparison JSON to this file"}
    )
    methods: str | None = field(
        default=None,
        metadata={
            "help": "comma-separated subset of: " + ", ".join(m.name for m in METHODS)
            + " (default: all; exif ones only when the photos have EXIF focal lengths)"
        },
    )


@dataclass(frozen=True)
class Comparison:
    ground_truth: GroundTruth | None
    methods: dict[str, dict[str, Any]]
    pairs: list[dict[str, Any]]
    fused: dict[str, Any]
    outputs: dict[str, Path]

    def as_json(self) -> dict[str, Any]:
        truth_pp = self.ground_truth.principal_point_px if self.ground_truth else None
        return {
            "ground_truth_focal_px": self.ground_truth.focal_px if self.ground_truth else None,
            "ground_truth_principal_point_px": list(truth_pp) if truth_pp else None,
            "ground_truth_source": self.ground_truth.source if self.ground_truth else None,
            "methods": self.methods,
            "kruppa_fused": self.fused,
            "pairs": self.pairs,
        }

    def lines(self) -> list[str]:
        truth = self.ground_truth
        truth_pp = truth.principal_point_px if truth else None
        out = [
            f"ground truth: {truth.focal_px:.1f} px ({truth.source})" if truth
            else "ground truth: none given (--gt)",
            *([f"ground truth principal point: ({truth_pp[0]:.1f}, {truth_pp[1]:.1f}) px"]
              if truth_pp else []),
            "",
            f"{'method':<20}{'focal px':>10}{'error':>9}{'registered':>12}{'reproj px':>11}"
            f"{'seconds':>9}{'principal point px':>22}{'pp error':>10}  mode",
        ]
        for name, m in self.methods.items():
            err = "" if m["rel_error"] is None else f"{100 * m['rel_error']:+.2f}%"
            focal = "failed" if m["focal_px"] is None else f"{m['focal_px']:.1f}"
            reproj = "" if m["mean_reproj_px"] is None else f"{m['mean_reproj_px']:.3f}"
            pp = m.get("principal_point_px")
            pp_text = f"({pp[0]:.1f}, {pp[1]:.1f})" if pp else ""
            pp_err = m.get("principal_point_error_px")
            pp_err_text = f"{pp_err:.1f}" if pp_err is not None else ""
            out.append(
                f"{name:<20}{focal:>10}{err:>9}{m['registered']:>7} of {m['images']:<3}"
                f"{reproj:>10}{m['seconds']:>9.1f}{pp_text:>22}{pp_err_text:>10}"
                f"  {m.get('mode', '')}"
                + ("  (fell back to colmap-default)" if m.get("fallback") else "")
            )
        ok = sum(p["status"] == "ok" for p in self.pairs)
        fused = (
            f"; fused {self.fused['focal_px']:.1f} px ±{self.fused.get('sigma_px') or 0:.1f}, "
            f"{self.fused['status']}"
            if self.fused.get("focal_px") is not None
            else f"; fused: {self.fused.get('status', 'not run')}"
        )
        out += [
            "",
            f"kruppa pairs: {ok} ok of {len(self.pairs)}{fused}",
            *(f"{k:<12}{v}" for k, v in self.outputs.items()),
        ]
        return out


def _selected(config: CompareConfig, ws: Workspace) -> list[Method]:
    names = [m.name for m in METHODS]
    if config.methods:
        wanted = [n.strip() for n in config.methods.split(",") if n.strip()]
        unknown = [n for n in wanted if n not in names]
        if unknown:
            raise UserError(
                f"unknown method(s) {', '.join(unknown)}; choose from {', '.join(names)}"
            )
        return [m for m in METHODS if m.name in wanted]
    has_exif = any(exif_focal_px(ws.images_dir / n) for n in ws.image_names()[:20])
    return [m for m in METHODS if has_exif or m.plugin != "exif"]


def _run_method(ws: Workspace, method: Method, sfm: SfMConfig, overwrite: bool) -> dict[str, Any]:
    branch = ws.branch(ws.root / "compare" / method.name, ("features", "matches"))
    config = SfMConfig(**{**sfm.__dict__, "intrinsics": method.plugin,
                          "intrinsics_options": method.options, "refine_focal": None})
    intrinsics = initialise_intrinsics(branch, config, overwrite=overwrite)
    priors = [c["focal_px"] for c in intrinsics.summary["cameras"] if c["prior"]]
    applied = intrinsics.summary["cameras"]
    points = [c["principal_point_px"] for c in applied if c.get("principal_point_px")]
    details = intrinsics.summary.get("details", {})
    result: dict[str, Any] = {
        "plugin": method.plugin,
        "options": list(method.options),
        "initial_focal_px": priors[0] if priors else None,
        "notes": intrinsics.summary.get("notes", []),
        "images": len(ws.image_names()),
        # The principal point mapping starts from and holds (COLMAP does not refine it by
        # default): the image centre unless the initialiser estimated one.
        "principal_point_px": (
            [sum(p[0] for p in points) / len(points), sum(p[1] for p in points) / len(points)]
            if points else None
        ),
        "mode": _mode(method, details, len(applied)),
        "principal_point_fit": details.get("principal_point") or None,
    }
    try:
        mapping = map_sparse(branch, config, overwrite=overwrite)
    except UserError as exc:
        return result | {
            "focal_px": None, "registered": 0, "mean_reproj_px": None,
            "seconds": intrinsics.seconds, "error": str(exc),
        }
    cams = mapping.summary["cameras"]
    details = intrinsics.summary.get("details", {})
    return result | {
        "fallback": bool(details.get("fallback", False)),
        "focal_px": sum(c["focal_px"] for c in cams) / len(cams),
        "focal_px_per_camera": {str(c["camera_id"]): c["focal_px"] for c in cams},
        "registered": mapping.summary["registered"],
        "mean_reproj_px": mapping.summary["mean_reprojection_error_px"],
        "seconds": intrinsics.seconds + mapping.seconds,
        "details": intrinsics.summary.get("details", {}),
    }


def _mode(method: Method, details: dict[str, Any], num_cameras: int) -> str:
    """Which Kruppa variant ran, in words, for the report."""
    if not method.plugin.startswith("kruppa"):
        return ""
    if details.get("camera_mode") == "per-image":
        return f"per-image focal ({num_cameras} camera(s))"
    mode = details.get("principal_point_mode")
    if mode in ("free", "epipolar"):
        fit = details.get("principal_point") or {}
        held = fit.get("held_at_centre") or []
        state = fit.get("status", "not fit")
        if state == "ok" and held:
            state = f"ok, c{held[0]} held at centre"
        how = " from the inliers" if mode == "epipolar" else ""
        return f"shared focal, free principal point{how} ({state})"
    return "shared focal, principal point at centre"


def compare_intrinsics(
    ws: Workspace, sfm: SfMConfig, config: CompareConfig, *, overwrite: bool = False
) -> Comparison:
    truth = None
    if config.gt is not None:
        try:
            truth = load_ground_truth(config.gt)
        except (ValueError, OSError) as exc:
            raise UserError(str(exc)) from None
    extract_features(ws, sfm, overwrite=overwrite)
    match_features(ws, sfm, overwrite=overwrite)
    methods: dict[str, dict[str, Any]] = {}
    for method in _selected(config, ws):
        entry = _run_method(ws, method, sfm, overwrite)
        entry["rel_error"] = (
            (entry["focal_px"] - truth.focal_px) / truth.focal_px
            if truth is not None and entry["focal_px"] is not None else None
        )
        pp = entry.get("principal_point_px")
        entry["principal_point_error_px"] = (
            math.dist(pp, truth.principal_point_px)
            if truth is not None and truth.principal_point_px is not None and pp else None
        )
        methods[method.name] = entry
    # The per-pair table of the centred closed form (the thesis' Table 4.1).
    kruppa = next(
        (m for m in methods.values()
         if m["plugin"] == "kruppa" and "camera_mode=per-image" not in m["options"]),
        None,
    )
    details = kruppa.get("details", {}) if kruppa else {}
    pairs, fused = details.get("pairs", []), details.get("fused", {})
    for entry in methods.values():
        entry.pop("details", None)
    outputs = _write_outputs(ws, truth, methods, pairs, fused, config)
    return Comparison(truth, methods, pairs, fused, outputs)


def _write_outputs(
    ws: Workspace,
    truth: GroundTruth | None,
    methods: dict[str, dict[str, Any]],
    pairs: list[dict[str, Any]],
    fused: dict[str, Any],
    config: CompareConfig,
) -> dict[str, Path]:
    from recon import plots  # matplotlib: only when there is something to plot

    folder = ws.root / "compare"
    folder.mkdir(exist_ok=True)
    comparison = Comparison(truth, methods, pairs, fused, {})
    data = comparison.as_json()
    outputs = {"json": folder / "comparison.json"}
    write_json_atomic(outputs["json"], data)
    if config.json is not None:
        config.json.parent.mkdir(parents=True, exist_ok=True)
        write_json_atomic(config.json, data)
        outputs["json_copy"] = config.json
    truth_px = truth.focal_px if truth else None
    if pairs:
        outputs["pairs_png"] = plots.pair_focals(
            folder / "pairs.png",
            [p["focal_px"] for p in pairs],
            [p["status"] for p in pairs],
            truth_px=truth_px,
            fused_px=fused.get("focal_px"),
            title=f"Kruppa focal per image pair ({ws.root.name})",
        )
    principal = {n: m["principal_point_px"] for n, m in methods.items()
                 if m.get("principal_point_px")}
    for n, m in methods.items():
        fit = m.get("principal_point_fit") or {}
        if fit.get("principal_point_px") and fit.get("status") != "ok":
            # The rejected estimate too: how far the pairs alone would have put it.
            principal[f"{n} fit, {fit['status']}"] = fit["principal_point_px"]
    if principal:
        first = next(iter(methods.values()))
        size = _image_size(ws)
        outputs["principal_points_png"] = plots.principal_points(
            folder / "principal_points.png", principal,
            truth_px=truth.principal_point_px if truth else None, image_size=size,
            title=f"Principal point by method ({ws.root.name}, {first['images']} images)",
        )
    if truth is not None:
        outputs["errors_png"] = plots.method_errors(
            folder / "errors.png",
            {n: m["rel_error"] for n, m in methods.items()},
            title=f"Focal error against truth ({ws.root.name})",
        )
    outputs["report"] = folder / "report.md"
    _write_report(outputs["report"], ws, comparison, outputs)
    outputs["recording"] = _log(ws, comparison)
    return outputs


def _image_size(ws: Workspace) -> tuple[int, int] | None:
    from PIL import Image

    names = ws.image_names()
    if not names:
        return None
    with Image.open(ws.images_dir / names[0]) as image:
        return image.size


def _write_report(path: Path, ws: Workspace, c: Comparison, outputs: dict[str, Path]) -> None:
    """Markdown report; ``c`` carries no outputs yet, so its summary lists none."""
    lines = [f"# Focal self-calibration compared: {ws.root.name}", ""]
    lines += ["```", *c.lines(), "```", ""]
    if "errors_png" in outputs:
        lines += ["![focal error by method](errors.png)", ""]
    if "principal_points_png" in outputs:
        lines += ["![principal point by method](principal_points.png)", ""]
    fits = {n: m for n, m in c.methods.items() if m.get("mode")}
    if fits:
        lines += ["## Kruppa variants", "",
                  "| method | mode | focal px | principal point px | notes |",
                  "|---|---|---|---|---|"]
        for name, m in fits.items():
            pp = m.get("principal_point_px")
            pp_text = f"({pp[0]:.1f}, {pp[1]:.1f})" if pp else ""
            focal = "" if m["focal_px"] is None else f"{m['focal_px']:.1f}"
            notes = "; ".join(m.get("notes", [])).replace("|", "/")
            lines.append(f"| {name} | {m['mode']} | {focal} | {pp_text} | {notes} |")
        lines.append("")
    if c.pairs:
        lines += [
            "## Kruppa per image pair (thesis Table 4.1)", "",
            "![per-pair focal](pairs.png)", "",
            "| image i | image j | focal px | status | conditioning | inliers |",
            "|---|---|---|---|---|---|",
        ]
        for p in c.pairs:
            focal = "" if p["focal_px"] is None else f"{p['focal_px']:.1f}"
            lines.append(f"| {p['image_i']} | {p['image_j']} | {focal} | {p['status']} | "
                         f"{p.get('conditioning', math.nan):.3g} | {p.get('inliers', '')} |")
    with atomic_output(path) as tmp:
        tmp.write_text("\n".join(lines) + "\n")


def _log(ws: Workspace, c: Comparison) -> Path:
    from recon import recording

    path = ws.log_path("compare")
    with recording.step_recording(path, "compare") as rec:
        rows = [
            {"method": n, "focal_px": m["focal_px"] if m["focal_px"] is not None else "failed",
             "rel_error": m["rel_error"] if m["rel_error"] is not None else "",
             "principal_point_px": str(m.get("principal_point_px") or ""),
             "mode": m.get("mode", ""),
             "registered": m["registered"], "seconds": m["seconds"]}
            for n, m in c.methods.items()
        ]
        recording.log_table(rec, "tables/methods", "Focal by method", rows)
        if c.pairs:
            values = [p["focal_px"] if p["focal_px"] is not None else math.nan for p in c.pairs]
            recording.log_series(rec, "pair", "kruppa/pair_focal_px", values)
            if c.ground_truth is not None:
                recording.log_series(rec, "pair", "kruppa/truth_focal_px",
                                     [c.ground_truth.focal_px] * len(values))
            recording.log_table(rec, "tables/pairs", "Kruppa per pair", c.pairs)
    return path
