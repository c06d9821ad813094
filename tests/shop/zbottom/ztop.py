#!/usr/bin/env python3
"""Re-express an AFM R-1000 machine file (or its machine-coordinate data)
that counts machine Z from the bottom of its travel so that it counts Z from
the top (Haas/Fanuc: machine zero at the top of travel, +Z up), the same
physical machine.

    ztop.py machine OLD.yaml > NEW.yaml
    ztop.py csv OLD.csv COLUMN... > NEW.csv     (columns shifted by -H)

With H the upper end of the old Z travel, every machine Z becomes z' = z - H
(the direction of +Z is kept). What moves with the origin
(machines/README.md, "The kinematic model"):

* the Z tables and the stiffness grid: positions shift by -H, values kept;
* workpiece-side angular errors rotate about the point of the table at
  machine zero: that point moves by h = (0, 0, H), so the translational
  tables of X and Y are re-expressed at the new point, d' = d + e x h
  (EXX += H*EB, EYX -= H*EA, the same for Y);
* the Z squareness (EA0Z, EB0Z) tilts the Z motion about machine zero of Z:
  with LOC the small-angle location HTM of Z, the Z translational tables get
  the constant c = h - LOC^-1 h (EXZ, EYZ, EZZ);
* the Z scale grows from the old zero: thermal scale_origin_mm = -H;
* work offsets and reference points: Z - H.

The text is edited line by line so comments and layout stay.
"""
import re
import sys

import yaml

DEC = 9  # decimals written (um): rounding <= 5e-10 um


def fmt(v):
    s = f"{v:.{DEC}f}".rstrip("0")
    if s.endswith("."):
        s += "0"
    if s == "-0.0":
        s = "0.0"
    return s


def flist(vs):
    return "[" + ", ".join(fmt(v) for v in vs) + "]"


def solve3(a, b):
    """Solve a 3x3 system by Cramer's rule."""
    def det(m):
        return (m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
                - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
                + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]))
    d = det(a)
    out = []
    for k in range(3):
        m = [row[:] for row in a]
        for i in range(3):
            m[i][k] = b[i]
        out.append(det(m) / d)
    return out


def convert_machine(text):
    doc = yaml.safe_load(text)
    axes = {a["name"]: a for a in doc["axes"]}
    z = axes["Z"]
    lo, hi = z["travel_mm"]
    H = float(hi)
    um = 1e-3  # urad * mm = 1e-3 um

    # New table values, per axis and key.
    new = {}
    for name in ("X", "Y"):
        ce = axes[name].get("component_errors", {})
        for lin, ang, sign in ((f"EX{name}_um", f"EB{name}_urad", 1.0),
                               (f"EY{name}_um", f"EA{name}_urad", -1.0)):
            if lin in ce and ang in ce:
                assert ce[lin]["positions_mm"] == ce[ang]["positions_mm"]
                new[(name, lin)] = {
                    d: [v + sign * H * um * w for v, w in zip(ce[lin][d], ce[ang][d])]
                    for d in ("forward", "reverse")}
    loc = z.get("location_errors", {})
    ea = loc.get("EA0Z_urad", 0.0) * 1e-6
    eb = loc.get("EB0Z_urad", 0.0) * 1e-6
    # LOC = small_angle(0, (ea, eb, 0)); c = h - LOC^-1 h (mm).
    m = [[1.0, 0.0, eb], [0.0, 1.0, -ea], [-eb, ea, 1.0]]
    v = solve3(m, [0.0, 0.0, H])
    c = [0.0 - v[0], 0.0 - v[1], H - v[2]]
    zce = z["component_errors"]
    for key, ci in (("EXZ_um", c[0]), ("EYZ_um", c[1]), ("EZZ_um", c[2])):
        new[("Z", key)] = {d: [x + ci * 1e3 for x in zce[key][d]]
                           for d in ("forward", "reverse")}

    out = []
    axis = None
    table = None
    section = None
    for line in text.splitlines():
        s = line.strip()
        if re.match(r"^[a-z_]+:", line):
            section = line.split(":")[0]
        mname = re.match(r"^\s*- name: (\w+)", line)
        if mname and section == "axes":
            axis = mname.group(1)
            table = None
        mt = re.match(r"^\s*(E\w+_(um|urad)):\s*$", line)
        if mt:
            table = mt.group(1)
        indent = line[: len(line) - len(line.lstrip())]
        if section == "axes" and axis == "Z" and s.startswith("travel_mm:"):
            line = f"{indent}travel_mm: {flist([lo - H, hi - H])}"
        elif section == "axes" and axis == "Z" and s.startswith("positions_mm:"):
            ps = yaml.safe_load(s.split(":", 1)[1])
            line = f"{indent}positions_mm: {flist([p - H for p in ps])}"
        elif section == "axes" and (axis, table) in new and s.split(":")[0] in ("forward", "reverse"):
            d = s.split(":")[0]
            line = f"{indent}{d}: {flist(new[(axis, table)][d])}"
        elif section in ("work_offsets_mm", "reference_points_mm"):
            mo = re.match(r"^(\s*[\w.]+): \[(.*)\](.*)$", line)
            if mo:
                x, y, zz = (float(t) for t in mo.group(2).split(","))
                line = f"{mo.group(1)}: [{x!r}, {y!r}, {zz - H!r}]{mo.group(3)}"
        elif section == "stiffness" and s.startswith("z: ["):
            ps = yaml.safe_load(s.split(":", 1)[1])
            line = f"{indent}z: {flist([p - H for p in ps])}"
        elif section == "thermal" and s.startswith("Z: {") and "scale_origin_mm" not in s:
            line = line.rstrip()[:-1].rstrip() + f", scale_origin_mm: {fmt(-H)} }}"
        out.append(line)
    return "\n".join(out) + "\n"


def convert_csv(text, columns, H=500.0):
    out = []
    idx = None
    for line in text.splitlines():
        if line.startswith("#") or not line.strip():
            out.append(line)
            continue
        cells = line.split(",")
        if idx is None:
            idx = [cells.index(c) for c in columns]
            out.append(line)
            continue
        for i in idx:
            cell = cells[i].strip()
            v = float(cell) - H
            decimals = len(cell.split(".")[1]) if "." in cell else 0
            if "e" in cell.lower() or decimals > 6:
                cells[i] = repr(v)  # shortest text that reads back as v
            else:
                cells[i] = f"{v:.{decimals}f}"
        out.append(",".join(cells))
    return "\n".join(out) + "\n"


if __name__ == "__main__":
    if sys.argv[1] == "machine":
        sys.stdout.write(convert_machine(open(sys.argv[2]).read()))
    elif sys.argv[1] == "csv":
        sys.stdout.write(convert_csv(open(sys.argv[2]).read(), sys.argv[3:]))
    else:
        sys.exit("usage: ztop.py machine FILE | csv FILE COLUMN...")
