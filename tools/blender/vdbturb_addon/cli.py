"""Drives the vdbturb executable: patterns, frame lists, command lines and a run in the background.

No bpy here: Blender's side (ui.py) calls these, and they run under any Python 3.
"""
import json
import os
import queue
import re
import shutil
import signal
import subprocess
import threading
import time

# The build writes the path of the vdbturb it built (or installed) into the zipped add-on under this name.
EXE_RECORD = "vdbturb_path.txt"

# vdbturb's frame tokens (README, Conventions): ####, @, %04d, $F4, ${F4}.
_TOKEN = re.compile(r"#+|@+|%0?\d*d|\$\{?F\d*\}?")
_NUMBERED = re.compile(r"^(.*?)(\d+)(\.vdb)$")
_PROGRESS = re.compile(r"^Progress: (\d+)%")
_ERROR = "vdbturb: error: "


def find_executable(preferred=""):
    """The vdbturb to run and where it came from: the preference, the build's record, or PATH."""
    if preferred:
        path = os.path.abspath(os.path.expanduser(preferred))
        if not (os.path.isfile(path) and os.access(path, os.X_OK)):
            raise FileNotFoundError(f"vdbturb executable '{preferred}' (add-on preferences) is not an executable file")
        return path, "preferences"
    record = os.path.join(os.path.dirname(os.path.abspath(__file__)), EXE_RECORD)
    if os.path.isfile(record):
        with open(record, encoding="utf-8") as f:
            path = f.read().strip()
        if os.path.isfile(path) and os.access(path, os.X_OK):
            return path, "recorded in the add-on by its build or install"
    path = shutil.which("vdbturb")
    if path:
        return path, "PATH"
    raise FileNotFoundError("no vdbturb executable: set its path in the add-on's preferences, or put vdbturb on PATH")


def sequence_pattern(path):
    """A vdbturb pattern for a folder of frames, a Blender cache folder, one frame of a sequence, or a pattern."""
    path = os.path.abspath(os.path.expanduser(path))
    if _TOKEN.search(os.path.basename(path)):
        # Padded tokens as #### (the same frames), which the add-on itself can list and name.
        name = re.sub(r"%0(\d+)d|\$\{?F(\d+)\}?", lambda m: "#" * int(m.group(1) or m.group(2)), os.path.basename(path))
        return os.path.join(os.path.dirname(path), name)
    if os.path.isdir(path):
        return _folder_pattern(path)
    m = _NUMBERED.match(os.path.basename(path))
    if m:  # one frame picked in the file browser stands for its sequence
        return os.path.join(os.path.dirname(path), m.group(1) + "#" * len(m.group(2)) + m.group(3))
    return path


def _folder_pattern(folder):
    names = [n for n in os.listdir(folder) if n.endswith(".vdb")]
    if not names and os.path.isdir(os.path.join(folder, "data")):
        # A Blender cache directory: the smoke's grids are in data/ (noise/ holds the noise up-res only).
        folder = os.path.join(folder, "data")
        names = [n for n in os.listdir(folder) if n.endswith(".vdb")]
    groups = {}
    for name in names:
        m = _NUMBERED.match(name)
        if m:
            groups.setdefault((m.group(1), len(m.group(2)), m.group(3)), []).append(name)
    if not groups:
        raise ValueError(f"{folder}: no numbered .vdb frames in this folder")
    # The longest sequence wins (a folder may also hold vdbturb's resume-state files or a stray frame).
    head, width, tail = max(groups, key=lambda k: len(groups[k]))
    return os.path.join(folder, head + "#" * width + tail)


def frames_on_disk(pattern):
    """The frame numbers of a ####-style pattern's files, sorted."""
    folder, name = os.path.split(pattern)
    m = re.fullmatch(r"(.*?)(#+)(.*)", name)
    if not m or not os.path.isdir(folder):
        return []
    rx = re.compile(re.escape(m.group(1)) + r"(\d{%d,})" % len(m.group(2)) + re.escape(m.group(3)) + "$")
    return sorted(int(r.group(1)) for r in map(rx.match, os.listdir(folder)) if r)


def frame_path(pattern, frame):
    """The file of one frame of a ####-style pattern."""
    return re.sub(r"#+", lambda m: str(frame).zfill(len(m.group(0))), pattern, count=1)


def parse_frames(text):
    """'1001-1100x2,1200' -> sorted frame numbers, as vdbturb's --frames reads them."""
    frames = set()
    for item in filter(None, (s.strip() for s in text.split(","))):
        m = re.fullmatch(r"(-?\d+)(?:-(-?\d+)(?:x(\d+))?)?", item)
        if not m:
            raise ValueError(f"frames '{text}': '{item}' is not N, A-B or A-BxS")
        first = int(m.group(1))
        last = int(m.group(2)) if m.group(2) is not None else first
        step = int(m.group(3) or 1)
        if last < first or step < 1:
            raise ValueError(f"frames '{text}': '{item}' runs backwards or has a step below 1")
        frames.update(range(first, last + 1, step))
    return sorted(frames)


def info(exe, path):
    """`vdbturb info --json` of one file, as a dict (its headers only: fast)."""
    run = subprocess.run([exe, "info", "--json", path], capture_output=True, text=True)
    if run.returncode != 0:
        raise RuntimeError(_error_of(run.stdout, run.stderr) or f"vdbturb info {path} failed ({run.returncode})")
    return json.loads(run.stdout)["files"][0]


def density_voxel(file_info):
    """The voxel size of a frame's density grid (the lattice vdbturb works on)."""
    for grid in file_info["grids"]:
        if grid.get("role") == "density" and grid.get("voxel_size"):
            return grid["voxel_size"]
    raise RuntimeError(f"{file_info.get('path', 'the frame')}: no density grid")


def dry_run(argv):
    """Runs a command line with --dry-run; returns (ok, the plan's main lines, short, and its warnings)."""
    run = subprocess.run(argv + ["--dry-run"], capture_output=True, text=True)
    if run.returncode != 0:
        return False, [_error_of(run.stdout, run.stderr) or f"exit {run.returncode}"]
    lines = []
    for line in run.stderr.splitlines():
        if line.startswith(("ratio", "output size", "memory", "time")):
            lines.append(line.split(" (")[0])  # the figure, not how it was found
        elif line.startswith("output lattice"):
            lines.append(line.split(", world")[0])
        elif line.startswith("vdbturb: warning: "):
            lines.append("warning: " + line[len("vdbturb: warning: "):])
    return True, lines


def _error_of(stdout, stderr):
    for line in reversed(stdout.splitlines()):
        try:
            doc = json.loads(line)
        except ValueError:
            continue
        if isinstance(doc, dict) and doc.get("error"):
            return doc["error"]
    errors = [line[len(_ERROR):] for line in stderr.splitlines() if line.startswith(_ERROR)]
    return errors[-1] if errors else ""


class Step:
    """One vdbturb command of a job, with its progress label."""

    def __init__(self, label, argv):
        self.label, self.argv = label, argv


class Job:
    """vdbturb commands run one after another in the background, their progress read from their output.

    Each command runs with --progress percent ("Progress: NN%" a frame, whatever the terminal) and, where it has
    one, --json (a JSON line per frame written). poll() never blocks: threads read the pipes into a queue.
    """

    def __init__(self, steps, log_path=None):
        self.steps = steps
        self.log_path = log_path
        self.state = "new"  # running, done, failed, cancelled
        self.step = -1
        self.percent = 0
        self.frames = []  # the JSON lines of frames written, in order
        self.history = []  # (step, percent) as each "Progress:" line arrived
        self.warnings = []
        self.error = ""
        self.returncode = None
        self.proc = None
        self._lines = queue.Queue()
        self._open_streams = 0
        self._log = None
        self._cancel_at = None

    @property
    def label(self):
        return self.steps[self.step].label if 0 <= self.step < len(self.steps) else ""

    @property
    def running(self):
        return self.state == "running"

    def start(self):
        if self.log_path:
            os.makedirs(os.path.dirname(self.log_path), exist_ok=True)
            self._log = open(self.log_path, "a", encoding="utf-8")
        self.state = "running"
        self._next_step()

    def _next_step(self):
        self.step += 1
        self.percent = 0
        argv = self.steps[self.step].argv
        if self._log:
            self._log.write("$ " + " ".join(argv) + "\n")
        # A session of its own: a Ctrl-C in Blender's terminal does not reach vdbturb, only Cancel does.
        self.proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, stdin=subprocess.DEVNULL,
                                     text=True, bufsize=1, start_new_session=True)
        self._open_streams = 2
        for name, stream in (("out", self.proc.stdout), ("err", self.proc.stderr)):
            threading.Thread(target=self._read, args=(name, stream), daemon=True).start()

    def _read(self, name, stream):
        with stream:
            for line in stream:
                self._lines.put((name, line.rstrip("\n")))
        self._lines.put((name, None))

    def poll(self):
        """Takes in what the commands printed so far and moves on; True while the job runs."""
        if not self.running:
            return False
        while True:
            try:
                name, line = self._lines.get_nowait()
            except queue.Empty:
                break
            if line is None:
                self._open_streams -= 1
            else:
                self._take(name, line)
        if self._cancel_at and self.proc.poll() is None and time.monotonic() - self._cancel_at > 20:
            self.proc.kill()  # vdbturb stops within a frame's stage; this is only for a hung process
        if self._open_streams == 0 and self.proc.poll() is not None:
            self._step_ended(self.proc.returncode)
        return self.running

    def _take(self, name, line):
        if self._log:
            self._log.write(line + "\n")
            self._log.flush()
        if name == "out" and line.startswith("{"):
            try:
                doc = json.loads(line)
            except ValueError:
                return
            if isinstance(doc, dict) and "frame" in doc and "out" in doc:
                self.frames.append(doc)
            elif isinstance(doc, dict) and doc.get("error"):
                self.error = doc["error"]
            return
        # "Progress:" is on stdout, or on stderr where --json holds stdout (resample has no --json).
        m = _PROGRESS.match(line)
        if m:
            self.percent = int(m.group(1))
            self.history.append((self.step, self.percent))
        elif line.startswith(_ERROR) and not self.error:
            self.error = line[len(_ERROR):]
        elif line.startswith("vdbturb: warning: "):
            self.warnings.append(line[len("vdbturb: warning: "):])

    def _step_ended(self, code):
        self.returncode = code
        last = self.step + 1 == len(self.steps)
        if self._cancel_at and not (code == 0 and last):  # a run that finished as Cancel came counts as done
            self._end("cancelled")
        elif code != 0:
            self.error = self.error or f"{os.path.basename(self.steps[self.step].argv[0])} exited with {code}"
            self._end("failed")
        elif not last:
            self._next_step()
        else:
            self._end("done")

    def _end(self, state):
        self.state = state
        if self._log:
            self._log.write(f"# {state} (exit {self.returncode})\n")
            self._log.close()
            self._log = None

    def cancel(self):
        """Asks vdbturb to stop (SIGTERM, as Ctrl-C): it finishes no new frame and leaves only whole ones."""
        if self.running and not self._cancel_at:
            self._cancel_at = time.monotonic()
            if self.proc.poll() is None:
                self.proc.send_signal(signal.SIGTERM)

    def wait(self, tick=None, interval=0.1):
        """Polls until the job ends (scripts, tests and the blocking operator); tick(job) after each poll."""
        while self.poll():
            if tick:
                tick(self)
            time.sleep(interval)
        if tick:
            tick(self)
        return self.state
