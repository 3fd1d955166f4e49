#!/usr/bin/python3
"""Writes a recording CSV as `rostopic echo -p /PSM1/measured_js` prints it:
%time in ns, the header fields, quoted joint names, then field.position0..,
field.velocity0.., field.effort0.. (usage: rostopic_seed.py IN.csv OUT_DIR)."""
import csv
import os
import sys

NAMES = ["outer_yaw", "outer_pitch", "outer_insertion", "outer_roll", "outer_wrist_pitch", "outer_wrist_yaw", "jaw"]
rows = list(csv.DictReader(open(sys.argv[1])))
n = sum(1 for k in rows[0] if k.startswith("position_"))
out_dir = sys.argv[2]
os.makedirs(out_dir, exist_ok=True)
for name, quoted in (("measured_js.csv", False), ("measured_js_quoted_names.csv", True)):
    header = ["%time", "field.header.seq", "field.header.stamp", "field.header.frame_id"]
    header += [f"field.name{j}" for j in range(n)]
    for what in ("position", "velocity", "effort"):
        header += [f"field.{what}{j}" for j in range(n)]
    lines = [",".join(header)]
    for seq, r in enumerate(rows):
        t_ns = 1700000000000000000 + round(float(r["time"]) * 1e9)
        cells = [str(t_ns), str(seq), str(t_ns), ""]
        cells += [(f'"{NAMES[j]}, {j}"' if quoted else NAMES[j]) for j in range(n)]
        for what in ("position", "velocity", "effort"):
            cells += [r[f"{what}_{j + 1}"] for j in range(n)]
        lines.append(",".join(cells))
    open(os.path.join(out_dir, name), "w").write("\n".join(lines) + "\n")
