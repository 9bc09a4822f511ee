"""The add-on's Blender-free half (tools/blender/vdbturb_addon/cli.py) under plain Python, with a stand-in
for vdbturb: patterns, frame lists, progress and exit codes, Cancel. ctest runs it as `blender_addon_cli`.

    python3 tests/blender/test_addon_cli.py
"""
import os
import stat
import sys
import tempfile
import time
import unittest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "tools", "blender",
                                "vdbturb_addon"))
import cli  # noqa: E402


def touch(folder, *names):
    os.makedirs(folder, exist_ok=True)
    for name in names:
        open(os.path.join(folder, name), "w").close()


class Patterns(unittest.TestCase):
    def test_a_blender_cache_folder_means_its_data_frames(self):
        with tempfile.TemporaryDirectory() as tmp:
            touch(os.path.join(tmp, "data"), "fluid_data_0001.vdb", "fluid_data_0002.vdb")
            touch(os.path.join(tmp, "noise"), "fluid_noise_0001.vdb")
            self.assertEqual(cli.sequence_pattern(tmp), os.path.join(tmp, "data", "fluid_data_####.vdb"))

    def test_the_longest_sequence_wins_and_resume_state_files_are_no_frames(self):
        with tempfile.TemporaryDirectory() as tmp:
            touch(tmp, "up_0001.vdb", "up_0002.vdb", "up_0003.vdb", "up_resume-state-odd.vdb", "stray.1.vdb")
            self.assertEqual(cli.sequence_pattern(tmp), os.path.join(tmp, "up_####.vdb"))
            self.assertEqual(cli.frames_on_disk(os.path.join(tmp, "up_####.vdb")), [1, 2, 3])

    def test_one_frame_or_a_padded_token_means_the_sequence(self):
        self.assertEqual(cli.sequence_pattern("/c/pyro.1001.vdb"), "/c/pyro.####.vdb")
        self.assertEqual(cli.sequence_pattern("/c/pyro.$F4.vdb"), "/c/pyro.####.vdb")
        self.assertEqual(cli.sequence_pattern("/c/pyro.%03d.vdb"), "/c/pyro.###.vdb")
        self.assertEqual(cli.frame_path("/c/pyro.####.vdb", 7), "/c/pyro.0007.vdb")

    def test_a_folder_without_frames_is_an_error(self):
        with tempfile.TemporaryDirectory() as tmp:
            with self.assertRaisesRegex(ValueError, "no numbered .vdb frames"):
                cli.sequence_pattern(tmp)

    def test_frame_lists_take_steps_and_refuse_nonsense(self):
        self.assertEqual(cli.parse_frames("1001-1005x2, 1010"), [1001, 1003, 1005, 1010])
        for bad in ("5-1", "1-9x0", "a-b"):
            with self.assertRaises(ValueError):
                cli.parse_frames(bad)


class Jobs(unittest.TestCase):
    """Job against a shell script that prints what vdbturb prints."""

    def script(self, folder, body):
        path = os.path.join(folder, "fake_vdbturb")
        with open(path, "w") as f:
            f.write("#!/bin/sh\n" + body)
        os.chmod(path, os.stat(path).st_mode | stat.S_IXUSR)
        return path

    def test_progress_frames_and_a_second_step(self):
        with tempfile.TemporaryDirectory() as tmp:
            exe = self.script(tmp, 'echo \'{"frame": 1, "out": "a"}\'; echo "Progress: 50%" >&2\n'
                                   'echo \'{"frame": 2, "out": "b"}\'; echo "Progress: 100%" >&2\n')
            os.makedirs(os.path.join(tmp, "p"))
            proxy = self.script(os.path.join(tmp, "p"), "echo 'Progress: 100%'\n")  # resample's: on stdout
            job = cli.Job([cli.Step("proxy", [proxy]), cli.Step("transfer", [exe])], os.path.join(tmp, "log"))
            job.start()
            self.assertEqual(job.wait(interval=0.01), "done")
            self.assertEqual(job.history, [(0, 100), (1, 50), (1, 100)])
            self.assertEqual([f["frame"] for f in job.frames], [1, 2])
            with open(os.path.join(tmp, "log")) as log:
                self.assertIn("# done (exit 0)", log.read())

    def test_a_failure_keeps_vdbturbs_message(self):
        with tempfile.TemporaryDirectory() as tmp:
            exe = self.script(tmp, 'echo "vdbturb: error: source x: no file matches" >&2; exit 1\n')
            job = cli.Job([cli.Step("transfer", [exe])])
            job.start()
            self.assertEqual(job.wait(interval=0.01), "failed")
            self.assertEqual((job.returncode, job.error), (1, "source x: no file matches"))

    def test_cancel_sends_sigterm_and_stops_the_steps(self):
        with tempfile.TemporaryDirectory() as tmp:
            # As vdbturb: SIGTERM ends the run with 130 after the frame in hand.
            exe = self.script(tmp, "trap 'exit 130' TERM\necho 'Progress: 10%' >&2\nwhile :; do sleep 0.05; done\n")
            job = cli.Job([cli.Step("transfer", [exe]), cli.Step("never", [exe])])
            job.start()
            while job.poll() and not job.history:
                time.sleep(0.01)
            job.cancel()
            self.assertEqual(job.wait(interval=0.01), "cancelled")
            self.assertEqual((job.returncode, job.step), (130, 0))


if __name__ == "__main__":
    unittest.main()
