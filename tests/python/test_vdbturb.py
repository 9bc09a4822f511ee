"""The Python module against the vdbturb executable (docs/python.md), under ctest: python_module.

Run by hand from the repository root after a build:
    PYTHONPATH=build/tools/python VDBTURB_EXE=build/tools/vdbturb /usr/bin/python3 -m unittest discover -s tests/python -v
One three-frame transfer of the Blender plume2 pair (32^3 target, 128^3 source) is made through the module and
through the executable, once for the whole file; about 20 s on two cores.
"""
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import unittest
import warnings

import numpy as np

import vdbturb

HERE = os.path.dirname(os.path.abspath(__file__))
DATA = os.environ.get("VDBTURB_SHARED_DATA", os.path.join(HERE, "..", "..", "..", "shared", "data"))
EXE = os.environ.get("VDBTURB_EXE", "vdbturb")
TARGET = os.path.join(DATA, "blender-plume2-32", "fluid_data_####.vdb")
SOURCE = os.path.join(DATA, "blender-plume2-128", "fluid_data_####.vdb")
# Settings off their defaults as a settings object (one by an older spelling), a negated flag and a frame list: they
# reach the parser as the CLI's options.
SETTINGS = dict(settings=vdbturb.TransferSettings(temporal_blend=0.9, seams_gamma=8.0), full_float=True, threads=2)
CLI_SETTINGS = ["--temporal-blend", "0.9", "--seams.gamma", "8", "--full-float", "--threads", "2"]
FRAMES = "1-3"

# An OpenVDB file's header holds a random UUID (36 characters at byte 21): every other byte must match.
UUID = slice(21, 57)


def cli(*args):
    """The executable's exit code, stdout and stderr."""
    p = subprocess.run([EXE, *args], capture_output=True, text=True)
    return p.returncode, p.stdout, p.stderr


def json_lines(text):
    return [json.loads(line) for line in text.splitlines() if line.strip()]


def without_timing(d):
    return {k: v for k, v in d.items() if k not in ("seconds",)}


def read_bytes(path):
    with open(path, "rb") as f:
        return f.read()


def same_vdb_bytes(a, b):
    x, y = read_bytes(a), read_bytes(b)
    return len(x) == len(y) and x[: UUID.start] + x[UUID.stop :] == y[: UUID.start] + y[UUID.stop :]


class ModuleAgainstCli(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.work = tempfile.mkdtemp(prefix="vdbturb_py_")
        cls.calls = []
        cls.module_out = os.path.join(cls.work, "module")
        cls.cli_out = os.path.join(cls.work, "cli")
        with warnings.catch_warnings(record=True) as cls.warned:
            warnings.simplefilter("always")
            cls.result = vdbturb.transfer(
                target=TARGET,
                source=SOURCE,
                out=os.path.join(cls.module_out, "o.####.vdb"),
                frames=FRAMES,
                progress=lambda frame, done, total: cls.calls.append((frame, done, total)),
                **SETTINGS,
            )
        code, _, err = cli("transfer", "--target", TARGET, "--source", SOURCE, "--out",
                           os.path.join(cls.cli_out, "o.####.vdb"), "--frames", FRAMES, "-q", *CLI_SETTINGS)
        assert code == 0, err

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.work, ignore_errors=True)

    def test_transfer_writes_the_cli_files_bit_for_bit(self):
        names = sorted(os.listdir(self.cli_out))
        self.assertEqual(names, sorted(os.listdir(self.module_out)))
        self.assertIn("o.0003.vdb", names)
        for n in names:  # the frames and the full-precision resume states
            self.assertTrue(same_vdb_bytes(os.path.join(self.cli_out, n), os.path.join(self.module_out, n)), n)
        self.assertEqual([f["frame"] for f in self.result["frames"]], [1, 2, 3])
        self.assertEqual(self.result["frames"][0]["out"], os.path.join(self.module_out, "o.0001.vdb"))
        self.assertEqual(self.result["summary"]["frames"], 3)

    def test_measure_numbers_equal_the_cli_on_the_same_run(self):
        out = os.path.join(self.module_out, "o.####.vdb")
        m = vdbturb.measure(output=out, target=TARGET, source=SOURCE, threads=2)
        code, stdout, err = cli("measure", "--output", out, "--target", TARGET, "--source", SOURCE, "--threads", "2")
        self.assertEqual(code, 0, err)
        lines = json_lines(stdout)
        self.assertEqual(len(m["frames"]), 3)
        self.assertEqual([without_timing(f) for f in m["frames"]], [without_timing(f) for f in lines[:-1]])
        self.assertIsNotNone(m["frames"][0]["lf_err"])
        metrics = {k: v for k, v in lines[-1].items() if isinstance(v, dict) and "mean" in v}
        self.assertIn("hf_ratio", metrics)
        for name, stats in metrics.items():
            self.assertEqual(m["summary"][name], stats, name)

    def test_settings_objects_check_values_as_the_cli_does(self):
        s = vdbturb.TransferSettings(temporalBlend=0.9, alignment="rotate")
        s.seams_enabled = False
        self.assertEqual((s.temporalBlend, s.alignment, s.seams_enabled), (0.9, "rotate", False))
        self.assertEqual(s.to_dict(), {"temporalBlend": 0.9, "alignment": "rotate", "seams_enabled": False})
        self.assertEqual(s.args(), ["--temporalBlend=0.9", "--alignment=rotate", "--seams.enabled=false"])
        self.assertEqual(vdbturb.TransferSettings().localPatch, 8)  # the library's default
        with self.assertRaisesRegex(ValueError, r"localPatch: 65 must be a finite number in \[2, 64\]"):
            vdbturb.TransferSettings(localPatch=65)
        with self.assertRaisesRegex(ValueError, "not one of none|normalize|rotate|both"):
            s.alignment = "sideways"
        with self.assertRaises(TypeError):
            s.localPatch = 8.5
        with self.assertRaisesRegex(AttributeError, "did you mean 'temporalBlend'"):
            s.temporalBlnd = 0.5
        with self.assertRaisesRegex(TypeError, "given as a keyword and in settings="):
            vdbturb.transfer(target=TARGET, source=SOURCE, out=os.path.join(self.work, "x.####.vdb"),
                             settings=vdbturb.TransferSettings(temporalBlend=0.5), temporal_blend=0.6)

    def test_settings_objects_describe_the_cli_defaults(self):
        described = vdbturb.TransferSettings.describe()
        code, out, err = cli("transfer", "--target", "t", "--source", "s", "--out", "o", "--print-settings")
        self.assertEqual(code, 0, err)
        self.assertGreater(len(described), 40)
        for keyword, row in described.items():
            option = row["option"][2:]
            line = next(l for l in out.splitlines() if l.startswith("# " + option + "="))
            printed = line.split("=", 1)[1].strip('"')
            default = row["default"]
            if isinstance(default, bool):
                self.assertEqual(printed, "true" if default else "false", keyword)
            elif isinstance(default, str):
                self.assertEqual(printed, default, keyword)
            else:  # numbers: as printed, read back in the field's type (a float 0.15 is 0.15 either way)
                self.assertAlmostEqual(float(printed), default, places=6, msg=keyword)

    def test_info_is_the_cli_report_as_a_dict(self):
        path = os.path.join(DATA, "blender-plume2-32", "fluid_data_0002.vdb")
        d = vdbturb.info(path)
        grids = [g["name"] for g in d["files"][0]["grids"]]
        self.assertIn("density", grids)
        self.assertIn("velocity", grids)
        code, stdout, err = cli("info", path, "--json")
        self.assertEqual(code, 0, err)
        self.assertEqual(d, json.loads(stdout))

    def test_warnings_are_python_warnings_and_stdout_stays_empty(self):
        self.assertTrue(any(issubclass(w.category, vdbturb.Warning) and "records no frame rate" in str(w.message)
                            for w in self.warned), [str(w.message) for w in self.warned])
        # A fresh interpreter: nothing of the commands' own on stdout or stderr (warnings go through `warnings`).
        script = ("import vdbturb, sys; vdbturb.info(sys.argv[1]); "
                  "vdbturb.measure(output=sys.argv[2], target=sys.argv[3], frames='1-2')")
        p = subprocess.run([sys.executable, "-c", script, os.path.join(DATA, "blender-plume2-32", "fluid_data_0002.vdb"),
                            os.path.join(self.module_out, "o.####.vdb"), TARGET], capture_output=True, text=True)
        self.assertEqual(p.returncode, 0, p.stderr)
        self.assertEqual(p.stdout, "")
        self.assertNotIn("vdbturb: ", p.stderr)

    def test_run_converts_and_info_reads_nanovdb(self):
        nvdb = os.path.join(self.work, "nano", "o.####.nvdb")
        docs = vdbturb.run(["convert", os.path.join(self.module_out, "o.####.vdb"), "--frames", "2", "--out", nvdb,
                            "--json"])
        self.assertEqual([d["frame"] for d in docs if "summary" not in d], [2])
        d = vdbturb.info(nvdb.replace("####", "0002"))
        self.assertIn("density", [g["name"] for g in d["files"][0]["grids"]])
        code, stdout, err = cli("info", nvdb.replace("####", "0002"), "--json")
        self.assertEqual(code, 0, err)
        self.assertEqual(d, json.loads(stdout))

    def test_preview_draws_the_cli_picture(self):
        cache = os.path.join(DATA, "blender-plume2-32", "fluid_data_####.vdb")
        module_png = os.path.join(self.work, "pic", "m.####.png")
        r = vdbturb.preview(cache, out=module_png, frames=[2], width=64, mode="density,speed", threads=2,
                            settings=vdbturb.PreviewSettings(exposure=2.0, speed_max=3.0))
        self.assertEqual([f["frame"] for f in r["frames"]], [2])
        code, _, err = cli("preview", cache, "--out", os.path.join(self.work, "pic", "c.####.png"), "--frames", "2",
                           "--width", "64", "--mode", "density,speed", "--threads", "2", "-q", "--exposure", "2",
                           "--speed-max", "3")
        self.assertEqual(code, 0, err)
        self.assertEqual(read_bytes(os.path.join(self.work, "pic", "m.0002.png")),
                         read_bytes(os.path.join(self.work, "pic", "c.0002.png")))

    def test_sim_and_measure_take_their_settings_objects(self):
        solver = vdbturb.SimSettings(scheme="semi", cfl=3.0)
        self.assertEqual(solver.args(), ["--scheme=semi", "--cfl=3"])
        mine, theirs = (os.path.join(self.work, "sim", n, "p.####.vdb") for n in ("module", "cli"))
        vdbturb.sim("plume", res="16", frames=2, out=mine, settings=solver, threads=2)
        code, _, err = cli("sim", "plume", "--res", "16", "--frames", "2", "--out", theirs, "--threads", "2", "-q",
                           "--scheme", "semi", "--cfl", "3")
        self.assertEqual(code, 0, err)
        for f in ("p.0001.vdb", "p.0002.vdb"):
            self.assertTrue(same_vdb_bytes(mine.replace("p.####.vdb", f), theirs.replace("p.####.vdb", f)), f)
        m = vdbturb.measure(output=mine, target=mine, settings=vdbturb.MeasureSettings(patchSize=4), threads=2)
        code, stdout, err = cli("measure", "--output", mine, "--target", mine, "--patchSize", "4", "--threads", "2")
        self.assertEqual(code, 0, err)
        self.assertEqual([without_timing(f) for f in m["frames"]], [without_timing(f) for f in json_lines(stdout)[:-1]])
        with self.assertRaisesRegex(ValueError, "patchSize"):
            vdbturb.MeasureSettings(patchSize=1)  # 0 (the metadata's) or 2..4096

    def test_progress_is_called_once_per_frame(self):
        self.assertEqual(self.calls, [(1, 1, 3), (2, 2, 3), (3, 3, 3)])

    def assert_only_whole_frames(self, folder, frames):
        self.assertEqual(sorted(f for f in os.listdir(folder) if not f.startswith("o.resume-state")),
                         ["o.%04d.vdb" % f for f in frames])
        for f in frames:  # the same frame as the full run's, so whole
            self.assertTrue(same_vdb_bytes(os.path.join(folder, "o.%04d.vdb" % f),
                                           os.path.join(self.module_out, "o.%04d.vdb" % f)))

    def test_progress_returning_false_cancels_with_whole_frames_only(self):
        out = os.path.join(self.work, "cancelled")
        with self.assertRaises(vdbturb.Cancelled) as c:
            vdbturb.transfer(target=TARGET, source=SOURCE, out=os.path.join(out, "o.####.vdb"), frames=FRAMES,
                             progress=lambda frame, done, total: False, **SETTINGS)
        self.assertEqual(c.exception.exit_code, 130)
        self.assertEqual(str(c.exception), "interrupted")  # the CLI's "vdbturb: error: interrupted"
        self.assertEqual([f["frame"] for f in c.exception.result], [1])
        self.assert_only_whole_frames(out, [1])

    def test_progress_raising_cancels_and_is_the_cause(self):
        out = os.path.join(self.work, "raised")

        def stop_at_two(frame, done, total):
            if frame == 2:
                raise KeyError("stop")

        with self.assertRaises(vdbturb.Cancelled) as c:
            vdbturb.transfer(target=TARGET, source=SOURCE, out=os.path.join(out, "o.####.vdb"), frames=FRAMES,
                             progress=stop_at_two, **SETTINGS)
        self.assertIsInstance(c.exception.__cause__, KeyError)
        self.assert_only_whole_frames(out, [1, 2])

    def test_ctrl_c_stops_at_a_frame_end_and_raises_keyboard_interrupt(self):
        out = os.path.join(self.work, "interrupted")
        previous = signal.signal(signal.SIGINT, signal.default_int_handler)
        try:
            with self.assertRaises(KeyboardInterrupt):
                vdbturb.transfer(target=TARGET, source=SOURCE, out=os.path.join(out, "o.####.vdb"), frames=FRAMES,
                                 progress=lambda frame, done, total: signal.raise_signal(signal.SIGINT), **SETTINGS)
        finally:
            signal.signal(signal.SIGINT, previous)
        self.assert_only_whole_frames(out, [1])

    def test_a_missing_input_raises_the_cli_message(self):
        missing = os.path.join(self.work, "nowhere", "low.####.vdb")
        args = dict(target=missing, source=SOURCE, out=os.path.join(self.work, "x", "o.####.vdb"))
        with self.assertRaises(vdbturb.InputError) as c:
            vdbturb.transfer(**args)
        code, _, err = cli("transfer", "--target", missing, "--source", SOURCE, "--out", args["out"])
        self.assertEqual(code, 1)
        self.assertEqual(c.exception.exit_code, 1)
        self.assertEqual("vdbturb: error: " + str(c.exception), err.strip())
        self.assertIn(missing, str(c.exception))
        self.assertEqual(c.exception.file, missing)
        self.assertIsInstance(c.exception, OSError)

    def test_a_bad_value_is_a_usage_error_with_the_cli_message(self):
        with self.assertRaises(vdbturb.UsageError) as c:
            vdbturb.transfer(target=TARGET, source=SOURCE, out=os.path.join(self.work, "x", "o.####.vdb"),
                             temporal_blend=2)
        self.assertEqual(c.exception.exit_code, 2)
        self.assertEqual(str(c.exception),
                         "--temporal-blend: must be a finite NUMBER in [0, 0.999] (--help lists the options)")

    def test_an_unknown_keyword_is_a_type_error_naming_the_nearest(self):
        with self.assertRaises(TypeError) as c:
            vdbturb.transfer(target=TARGET, source=SOURCE, out="o.####.vdb", temporal_blen=0.9)
        self.assertIn("'temporal_blen'", str(c.exception))
        self.assertIn("did you mean 'temporal_blend'?", str(c.exception))

    def test_the_gil_is_released_while_a_transfer_runs(self):
        count = [0]
        stop = threading.Event()

        def spin():
            while not stop.is_set():
                count[0] += 1

        t = threading.Thread(target=spin)
        t.start()
        try:
            before = count[0]
            vdbturb.transfer(target=TARGET, source=SOURCE, out=os.path.join(self.work, "gil", "o.####.vdb"),
                             frames="1-2", threads=1)
            during = count[0] - before
        finally:
            stop.set()
            t.join()
        # Held for the whole call, the spinner would get the GIL only at the two frame callbacks.
        self.assertGreater(during, 100000)


class MeasureArrays(unittest.TestCase):
    def test_known_numbers_of_an_analytic_frame(self):
        f, a = 2, 0.25
        target_density = np.ones((8, 8, 8), np.float32)
        target_velocity = np.zeros((8, 8, 8, 3), np.float32)
        target_velocity[..., 0] = 1.0
        # The output: the target's constant flow plus a detail of zero mean in every f^3 block (a checkerboard
        # of +-a along x), so boxdown(U_out) = U_t: lf_err = 0, hf_energy = a^2; the density copied per block.
        x = np.arange(16)
        checker = np.where((x[:, None, None] + x[None, :, None] + x[None, None, :]) % 2 == 0, a, -a)
        out_velocity = np.repeat(np.repeat(np.repeat(target_velocity, f, 0), f, 1), f, 2).copy()
        out_velocity[..., 0] += checker
        out_density = np.ones((16, 16, 16), np.float32)
        m = vdbturb.measure_arrays(out_velocity, out_density, target_velocity, target_density, voxel_size=0.1)
        self.assertEqual(m["ratio"], 2)
        self.assertAlmostEqual(m["lf_err"], 0.0, places=6)
        self.assertAlmostEqual(m["hf_energy"], a * a, places=5)
        self.assertAlmostEqual(m["mass_ratio"], 1.0, places=6)
        self.assertAlmostEqual(m["peak_ratio"], 1.0, places=6)
        self.assertIsNone(m["hf_ratio"])  # no source given

    def test_shapes_are_checked(self):
        with self.assertRaises(ValueError):
            vdbturb.measure_arrays(np.zeros((15, 16, 16, 3)), None, np.zeros((8, 8, 8, 3)), np.ones((8, 8, 8)),
                                   voxel_size=0.1)


if __name__ == "__main__":
    unittest.main()
