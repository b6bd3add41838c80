"""ROS bags through the Python module: `import lex3d` does not load the ROS libraries, the
first bag read loads the plugin (liblex3d_rosbag.so) and gives the same bytes as the command
on the same bag, and without the plugin a bag raises ValueError naming the file. Run by ctest
(python.tests), which sets LEX3D_CLI; skipped when lex3d was built without ROS bag support."""

import os
import pathlib
import subprocess
import sys

import pytest

import lex3d

SAMPLES = pathlib.Path(os.environ.get("LEX3D_SAMPLES", pathlib.Path(__file__).parents[2] / "samples"))
CLI = os.environ.get("LEX3D_CLI")

pytestmark = pytest.mark.skipif(not CLI, reason="LEX3D_CLI not set (run through ctest)")


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    """A sample scan written as a one-message bag by the command."""
    path = tmp_path_factory.mktemp("bags") / "scan.bag"
    r = subprocess.run([CLI, "convert", str(SAMPLES / "newer_college_00.bin"), str(path)],
                       capture_output=True, text=True)
    if r.returncode != 0 and "without ROS bag support" in r.stderr:
        pytest.skip("lex3d built without ROS bag support")
    assert r.returncode == 0, r.stderr
    return path


def run_python(code, **env):
    """`code` in a fresh interpreter with the module under test; its stdout, stderr, exit code."""
    e = dict(os.environ, **env)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=e)
    return r.stdout, r.stderr, r.returncode


LOADED = "import re; maps = open('/proc/self/maps').read(); " \
         "print(sorted(set(re.findall(r'lib(?:rosbag_storage|roscpp_serialization|boost_\\w+|lex3d_rosbag)\\.so', maps))))"


def test_import_does_not_load_the_ros_libraries_and_a_bag_does(bag):
    out, err, rc = run_python("import lex3d; " + LOADED)
    assert rc == 0, err
    assert out.strip() == "[]"
    out, err, rc = run_python(f"import lex3d; lex3d.compress({str(bag)!r}, max_error=0.02); " + LOADED)
    assert rc == 0, err
    assert "liblex3d_rosbag.so" in out and "librosbag_storage.so" in out


def test_a_bag_compresses_to_the_commands_bytes(bag, tmp_path):
    out = tmp_path / "scan.lex3dm"
    subprocess.run([CLI, "compress", str(bag), "-o", str(out), "--max-error", "0.014"], check=True, capture_output=True)
    assert lex3d.compress(bag, max_error=0.014) == out.read_bytes()


def test_without_the_plugin_a_bag_raises_value_error_naming_it(bag, tmp_path):
    missing = tmp_path / "nowhere" / "liblex3d_rosbag.so"
    code = f"import lex3d\ntry:\n    lex3d.compress({str(bag)!r}, max_error=0.02)\nexcept ValueError as e:\n    print(e)"
    out, err, rc = run_python(code, LEX3D_ROSBAG_PLUGIN=str(missing))
    assert rc == 0, err
    assert out.startswith(str(bag) + ": ROS bag support is not installed")
    assert out.count("\n") == 1
