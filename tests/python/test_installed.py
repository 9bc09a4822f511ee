"""The module as `cmake --install` lays it out, without the build tree (docs/python.md), under ctest: python_install.

Needs VDBTURB_BUILD_DIR (the build tree to install) and CMAKE_COMMAND; installs into a temporary prefix (about
40 MB, under a second), then imports the module from PREFIX/lib/python3.X/dist-packages in a fresh interpreter.
"""
import os
import subprocess
import sys
import sysconfig
import tempfile
import unittest

BUILD = os.environ.get("VDBTURB_BUILD_DIR", "")
CMAKE = os.environ.get("CMAKE_COMMAND", "cmake")

CHECK = r"""
import os, sys
import numpy as np
import vdbturb
prefix, build = sys.argv[1], sys.argv[2]
assert vdbturb.__file__.startswith(prefix), vdbturb.__file__
r = vdbturb.sim("plume", res="8x8x12", frames=2, out=os.path.join(prefix, "sim", "plume.####.vdb"), threads=1)
assert [f["frame"] for f in r["frames"]] == [1, 2], r
d = vdbturb.info(os.path.join(prefix, "sim", "plume.0002.vdb"))
assert "density" in [g["name"] for g in d["files"][0]["grids"]], d
# An image: OpenImageIO's module, loaded on first use, must be found in the prefix too.
p = vdbturb.preview(os.path.join(prefix, "sim", "plume.####.vdb"), out=os.path.join(prefix, "pic.####.png"),
                    width=32, frames=[2])
assert os.path.getsize(os.path.join(prefix, "pic.0002.png")) > 0, p
m = vdbturb.measure_arrays(np.zeros((8, 8, 8, 3)), np.ones((8, 8, 8)), np.zeros((4, 4, 4, 3)), np.ones((4, 4, 4)),
                           voxel_size=0.1)
assert abs(m["mass_ratio"] - 1.0) < 1e-6, m
# Every library the module loaded comes from the prefix or the system, none from the build tree.
maps = open("/proc/self/maps").read()
assert build not in maps, [l for l in maps.splitlines() if build in l][:3]
print("installed module ok:", vdbturb.__file__)
"""


@unittest.skipUnless(BUILD, "VDBTURB_BUILD_DIR is not set")
class InstalledModule(unittest.TestCase):
    def test_imports_and_runs_from_the_install_prefix(self):
        with tempfile.TemporaryDirectory(prefix="vdbturb_pyinst_") as prefix:
            subprocess.run([CMAKE, "--install", BUILD, "--prefix", prefix], check=True, stdout=subprocess.DEVNULL)
            site = os.path.join(prefix, "lib", "python%d.%d" % sys.version_info[:2],
                                "dist-packages" if "dist-packages" in sysconfig.get_path("platlib")
                                else "site-packages")
            self.assertTrue(any(n.startswith("vdbturb") and n.endswith(".so") for n in os.listdir(site)), site)
            env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "LD_LIBRARY_PATH")}
            env["PYTHONPATH"] = site
            p = subprocess.run([sys.executable, "-c", CHECK, prefix, os.path.realpath(BUILD)], cwd=prefix, env=env,
                               capture_output=True, text=True)
            self.assertEqual(p.returncode, 0, p.stdout + p.stderr)
            self.assertIn("installed module ok", p.stdout)


if __name__ == "__main__":
    unittest.main()
