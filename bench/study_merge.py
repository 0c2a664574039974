#!/usr/bin/env python3
"""Merge the parts of a study run in pieces (bench/study_gpu.sh runs the walls,
the meshes and the dynamics separately, and the GPU machine returns study.json
files) into one folder: study_detect.csv and study_dynamics.csv (and with
--json study.json, the same rows as one document), written as `collidoscope
study` writes them (study/study_io.cpp: the columns in the rows' order, numbers
to 6 significant digits, booleans 1/0, missing values empty, text quoted where
it must be).

Usage: bench/study_merge.py [--json] OUT_DIR PART/study.json [PART/study.json ...]
"""
import json
import os
import sys


def field(v):
    if v is None:
        return ""
    if isinstance(v, bool):
        return "1" if v else "0"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return f"{v:.6g}"
    s = str(v)
    if any(c in s for c in ',"\n\r'):
        return '"' + s.replace('"', '""') + '"'
    return s


def write_csv(path, rows):
    if not rows:
        return
    with open(path + ".tmp", "w") as f:
        f.write(",".join(rows[0].keys()) + "\n")
        for r in rows:
            f.write(",".join(field(v) for v in r.values()) + "\n")
    os.replace(path + ".tmp", path)


def main(argv):
    want_json = "--json" in argv
    argv = [a for a in argv if a != "--json"]
    if len(argv) < 2:
        sys.exit(__doc__)
    out, parts = argv[0], [json.load(open(p)) for p in argv[1:]]
    os.makedirs(out, exist_ok=True)
    doc = {"machine": parts[0]["machine"],
           "detect": [r for p in parts for r in p["detect"]],
           "dynamics": [r for p in parts for r in p["dynamics"]]}
    write_csv(os.path.join(out, "study_detect.csv"), doc["detect"])
    write_csv(os.path.join(out, "study_dynamics.csv"), doc["dynamics"])
    if want_json:
        with open(os.path.join(out, "study.json.tmp"), "w") as f:
            json.dump(doc, f, indent=1)
            f.write("\n")
        os.replace(os.path.join(out, "study.json.tmp"), os.path.join(out, "study.json"))
    print(f"{out}: {len(doc['detect'])} detection rows, {len(doc['dynamics'])} dynamics rows")


if __name__ == "__main__":
    main(sys.argv[1:])
