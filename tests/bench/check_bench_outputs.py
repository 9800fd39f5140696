#!/usr/bin/python3
"""Checks what `u3mscan bench --quick --keep-work -o DIR` wrote: bench.csv with the expected
columns and one ok row per case of the quick matrix, bench.md with its tables, four SVG plots that
parse as XML; then runs `u3mscan evaluate` (second argument: the executable) on one kept run."""
import csv
import json
import re
import subprocess
import sys
import xml.dom.minidom
from pathlib import Path

EXPECTED_COLUMNS = [
    "group", "scene", "rig", "size_px", "camera_per_map", "maps_dpi", "ps_supersample", "level", "megapixels", "lights", "calibration_frames", "sensor_noise", "preset", "solver", "integrator",
    "fit_mode", "follow_fibres", "status", "wall_s", "total_s", "peak_rss_mib", "read_s", "calibration_s", "rectify_s", "alpha_s",
    "photometric_stereo_s", "integration_s", "fit_s", "write_s", "steps_skipped", "normal_mean_deg",
    "normal_median_deg", "normal_p95_deg", "albedo_de2000", "base_color_de2000", "height_rmse_mm",
    "height_rmse_pct", "height_levelled_rmse_pct", "roughness_err", "specular_err", "specular_tint_err", "sheen_err", "sheen_tint_err",
    "anisotropic_err", "metallic_err", "rerender_rel_rmse", "rerender_truth_maps_rel_rmse", "held_out_rel_rmse", "unreliable",
    "error"]
PLOTS = ["error_vs_time.svg", "rerender_vs_time.svg", "time_vs_megapixels.svg", "time_vs_lights.svg"]


def fail(message):
    print("FAIL:", message)
    sys.exit(1)


def main():
    out = Path(sys.argv[1])
    with open(out / "bench.csv", newline="") as f:
        rows = list(csv.reader(f))
    if rows[0] != EXPECTED_COLUMNS:
        fail(f"bench.csv columns {rows[0]}")
    records = [dict(zip(rows[0], r)) for r in rows[1:]]
    if len(records) < 10:
        fail(f"only {len(records)} rows")
    for r in records:
        if len(r) != len(EXPECTED_COLUMNS):
            fail(f"row with {len(r)} cells")
        if r["status"] != "ok":
            fail(f"run failed: {r}")
        for column in ("total_s", "peak_rss_mib", "normal_mean_deg", "height_rmse_mm", "rerender_rel_rmse"):
            if not float(r[column]) >= 0.0:
                fail(f"{column} = {r[column]!r}")
        if float(r["normal_mean_deg"]) > 90.0:
            fail(f"normal error out of range: {r['normal_mean_deg']}")
        # A levelled run also has its height against the truth levelled alike; none has none.
        if (r["level"] != "none") != (r["height_levelled_rmse_pct"] != ""):
            fail(f"height_levelled_rmse_pct {r['height_levelled_rmse_pct']!r} for level {r['level']!r}")
        if r["height_levelled_rmse_pct"] and not float(r["height_levelled_rmse_pct"]) >= 0.0:
            fail(f"height_levelled_rmse_pct = {r['height_levelled_rmse_pct']!r}")
    if {r["preset"] for r in records} != {"fast", "balanced", "best"}:
        fail("not every preset ran")
    if not {"distant", "near", "oblique"} <= {r["rig"] for r in records}:
        fail("rigs missing")
    if {r["solver"] for r in records} != {"ls", "robust"} or {r["integrator"] for r in records} != {"dct", "robust"}:
        fail("method comparison missing")
    if {r["fit_mode"] for r in records} != {"clusters", "per-pixel"}:
        fail("fit mode comparison missing")
    if not any(r["calibration_frames"] == "no" for r in records):
        fail("no capture without calibration frames")
    held_out = [r for r in records if r["group"] == "held-out"]
    if not held_out or not all(0.0 <= float(r["held_out_rel_rmse"]) < 1.0 for r in held_out):
        fail(f"held-out run missing or its held_out_rel_rmse out of range: {held_out}")
    if any(r["held_out_rel_rmse"] for r in records if r["group"] != "held-out"):
        fail("held_out_rel_rmse filled for a run that held no light out")
    # The truth's own maps re-render as the truth on its own grid when the scene is Principled, and
    # not on a coarser grid; under model mismatch (velvet_mismatch, Charlie sheen) they are a
    # Principled material against the fabric, never the fabric itself.
    if any(float(r["rerender_truth_maps_rel_rmse"]) != 0.0 for r in records
           if r["camera_per_map"] == "1" and r["scene"] != "velvet_mismatch"):
        fail("rerender_truth_maps_rel_rmse not 0 for a run of a Principled scene on the truth's own grid")
    if not all(float(r["rerender_truth_maps_rel_rmse"]) > 0.0 for r in records if r["scene"] == "velvet_mismatch"):
        fail("rerender_truth_maps_rel_rmse 0 under model mismatch: the truth was not rendered with its own model")
    finer = [r for r in records if r["group"] == "camera-finer"]
    if not finer or any(int(r["camera_per_map"]) < 2 for r in finer):
        fail(f"camera-finer run missing or its camera_per_map below 2: {finer}")
    if not all(float(r["rerender_truth_maps_rel_rmse"]) > 0.0 for r in finer):
        fail(f"rerender_truth_maps_rel_rmse 0 on a grid coarser than the truth: {finer}")
    if any(r["camera_per_map"] != "1" for r in records if r["group"] != "camera-finer"):
        fail("camera_per_map other than 1 outside the camera-finer group")
    if sorted((r["ps_supersample"], r["level"]) for r in finer) != [("0", "plane"), ("0", "quadratic"), ("1", "plane")]:
        fail(f"camera-finer runs should have photometric stereo on the maps' grid (1) and the camera's (0), "
             f"the latter also with --level quadratic: {finer}")
    if any(r["level"] != "plane" for r in records if r["group"] != "camera-finer"):
        fail("level other than plane outside the camera-finer group")
    if any(r["ps_supersample"] != "1" for r in records if r["group"] != "camera-finer"):
        fail("ps_supersample other than 1 outside the camera-finer group")
    at_1x = {(r["scene"], r["rig"], r["preset"]): r for r in records if r["group"] == "matrix"}
    for r in finer:
        same = at_1x.get((r["scene"], r["rig"], r["preset"]))
        # The same sample on the same 300 dpi grid: the finer camera must not change the map's size.
        if same and abs(float(same["megapixels"]) - float(r["megapixels"])) > 0.1 * float(same["megapixels"]):
            fail(f"camera-finer map size {r['megapixels']} MP differs from the 1x run's {same['megapixels']} MP")
    mismatch = [r for r in records if r["group"] == "model-mismatch"]
    if [r["scene"] for r in mismatch] != ["velvet_mismatch"]:
        fail(f"one model-mismatch run (velvet_mismatch) expected: {mismatch}")
    md = (out / "bench.md").read_text(encoding="utf-8")
    # Its row in the mismatch table, beside the Principled velvet of the same rig and preset.
    if "| velvet_mismatch_distant_48 | fast |" not in md or "velvet_distant_48_fast" not in {
            r["scene"] + "_" + r["rig"] + "_" + r["size_px"] + "_" + r["preset"] for r in records}:
        fail("bench.md lacks the model-mismatch row or its Principled velvet run")
    for heading in ("## Every run", "## Presets", "## Methods on the same capture",
                    "### Fit: clusters vs per-pixel", "## Held-out photographs", "## Camera finer than the maps",
                    "## Scenes that need less", "## Model mismatch", "## Against the issues' targets"):
        if heading not in md:
            fail(f"bench.md lacks {heading}")
    # The plain balanced matrix run judged against the issues' limits: marked figures and their count.
    targets = md.split("## Against the issues' targets")[1].split("\n## ")[0]
    judged = [line for line in targets.splitlines() if line.startswith("| plain_distant_48_balanced |")]
    if (len(judged) != 1 or not re.search(r"\| \d+ of [1-9]\d* \| [^|]+ \|$", judged[0])
            or ("✓" not in judged[0] and "✗" not in judged[0])):
        fail(f"the targets table lacks the judged plain_distant_48_balanced run: {judged}")
    for plot in PLOTS:
        document = xml.dom.minidom.parse(str(out / plot))
        if document.documentElement.tagName != "svg":
            fail(f"{plot} is not SVG")
        if not document.getElementsByTagName("circle"):
            fail(f"{plot} has no points")
    # `u3mscan evaluate` on a kept run: every figure printed, the JSON written, bad input -> exit 2.
    u3mscan = sys.argv[2]
    run = out / "work" / "runs" / "plain_distant_48_fast"
    truth = out / "work" / "captures" / "plain_distant_48" / "truth"
    result = subprocess.run([u3mscan, "evaluate", str(run), str(truth), "--json", str(out / "evaluate.json")],
                            capture_output=True, text=True)
    if result.returncode != 0:
        fail(f"evaluate exit {result.returncode}: {result.stderr}")
    for text in ("normal angular error", "albedo CIEDE2000", "height RMSE", "roughness", "re-render",
                 "issues' targets (scene plain"):
        if text not in result.stdout:
            fail(f"evaluate did not print {text!r}: {result.stdout}")
    figures = json.loads((out / "evaluate.json").read_text())
    # The targets judged from the same figures: the normal against plain's 1 deg limit.
    normal_check = next((t for t in figures.get("targets", []) if t["figure"] == "normal mean deg"), None)
    if (figures.get("scene") != "plain" or normal_check is None or normal_check["limit"] != 1.0
            or normal_check["met"] != (figures["normal_error_deg"]["mean"] < 1.0)):
        fail(f"evaluate.json lacks the scene or the normal's verdict: {figures.get('scene')}, {normal_check}")
    row = next(r for r in records if r["group"] == "matrix" and r["rig"] == "distant" and r["preset"] == "fast")
    if abs(figures["normal_error_deg"]["mean"] - float(row["normal_mean_deg"])) > 1e-3:
        fail("evaluate and bench disagree on the normal error")
    bad = subprocess.run([u3mscan, "evaluate", str(out / "nowhere"), str(truth)], capture_output=True, text=True)
    if bad.returncode != 2 or "report.json" not in bad.stderr:
        fail(f"evaluate on a missing output: exit {bad.returncode}, {bad.stderr!r}")
    print(f"ok: {len(records)} runs")


main()
