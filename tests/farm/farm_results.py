"""What check_farm.py and check_tiles.py both read: a plan's frame list and `measure`'s per-frame JSON lines."""
import json


def frames_of(spec):
    """The frames of a frame list as vdbturb writes it ("1-30", "1001-1100x2,1200")."""
    out = []
    for part in spec.split(","):
        step = 1
        if "x" in part:
            part, s = part.split("x"); step = int(s)
        if "-" in part[1:]:
            i = part.index("-", 1)
            out += list(range(int(part[:i]), int(part[i + 1:]) + 1, step))
        else:
            out.append(int(part))
    return out


def measure(path):
    """`measure`'s per-frame JSON lines by frame number (the summary line has no frame)."""
    rows = {}
    for line in open(path):
        line = line.strip()
        if line.startswith("{"):
            j = json.loads(line)
            if "frame" in j and "lf_err" in j:
                rows[j["frame"]] = j
    return rows
