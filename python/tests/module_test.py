"""The fibremss Python module: scenes, views without copies, stepping, errors, and results that
match the command-line tool's for the same scene and settings.

Run with the build's module on the path: PYTHONPATH=build/python python3 module_test.py.
FIBREMSS_CLI names the fibremss tool for the comparisons with it (skipped without)."""
import gc
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
import unittest

try:
    import numpy as np
except ImportError:
    print("numpy is not installed: skipped")
    sys.exit(77)

import fibremss

SMALL = {"resolution": 8}  # fusiform at 8 particles per fibre: 512 particles, 3 poses
CLI = os.environ.get("FIBREMSS_CLI", "")


def box(lower, upper):
    """A closed box mesh, triangles counter-clockwise from outside."""
    corners = [[(lower, upper)[(i >> axis) & 1][axis] for axis in range(3)] for i in range(8)]
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    triangles = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    return {"vertices": np.array(corners, float), "triangles": np.array(triangles)}


def bar_scene(pull_mm):
    """A 100 mm bar of muscle between two bone blocks; the right one pulls it over 3 poses."""
    muscle = box([0, -0.01, -0.01], [0.1, 0.01, 0.01])
    grid = (-0.006, 0, 0.006)
    muscle["fibres"] = [np.array([[0, y, z], [0.1, y, z]]) for y in grid for z in grid]
    poses = [np.eye(4) for _ in range(3)]
    for i, pose in enumerate(poses):
        pose[0, 3] = 0.5e-3 * pull_mm * i
    return fibremss.build_scene(
        "bar",
        [dict(name="left", **box([-0.02, -0.02, -0.02], [0, 0.02, 0.02])),
         dict(name="right", **box([0.1, -0.02, -0.02], [0.12, 0.02, 0.02]))],
        [dict(name="bar", resolution=10, **muscle)],
        {"right": poses})


def stepped(scene, poses):
    """A one-thread simulation of the scene stepped through its first `poses` poses."""
    simulation = fibremss.Simulation(scene, threads=1)
    for pose in range(poses):
        simulation.set_pose(pose)
        simulation.step()
    return simulation


def run_cli(*args):
    """Runs the fibremss tool; its completed process."""
    return subprocess.run([CLI, *args], check=True, capture_output=True, text=True)


class Scenes(unittest.TestCase):
    def test_built_in_scenes_load_with_overrides(self):
        names = [name for name, _ in fibremss.scenes()]
        self.assertIn("fusiform", names)
        scene = fibremss.load_scene("fusiform", {"resolution": 8, "iterations": 7})
        self.assertEqual(scene.iterations, 7)
        self.assertEqual(scene.muscle_names, ["fusiform"])
        self.assertEqual(json.loads(scene.json)["muscles"][0]["resolution"], 8)
        self.assertEqual(fibremss.load_scene("fusiform", ["iterations=7"]).iterations, 7)

    def test_a_scene_file_loads(self):
        with tempfile.TemporaryDirectory() as out:
            path = os.path.join(out, "mine.json")
            with open(path, "w") as f:
                f.write(fibremss.export_scene("fusiform"))
            scene = fibremss.load_scene(path, SMALL)
        self.assertEqual((scene.name, scene.source), ("fusiform", path))
        self.assertEqual(scene.pose_count, fibremss.load_scene("fusiform").pose_count)

    def test_bone_pose_is_a_rigid_4x4(self):
        scene = fibremss.load_scene("fusiform", SMALL)
        pose = scene.bone_pose(1, scene.pose_count - 1)
        self.assertEqual(pose.shape, (4, 4))
        np.testing.assert_allclose(pose[:3, :3] @ pose[:3, :3].T, np.eye(3), atol=1e-6)
        self.assertFalse(np.allclose(pose, np.eye(4)))  # the lower bar moved

    def test_a_built_scene_stretches_when_its_bone_pulls(self):
        rest = stepped(bar_scene(0), 3).measures()[0]
        pulled = stepped(bar_scene(4), 3).measures()[0]
        self.assertTrue(pulled["finite"])
        self.assertGreater(pulled["max_fibre_stretch"], rest["max_fibre_stretch"])
        self.assertEqual(len(pulled["penetration_mm"]), 2)
        summary = fibremss.run(bar_scene(4), threads=1)
        self.assertEqual((summary["steps"], summary["muscles"][0]["name"]), (3, "bar"))

    def test_ctrl_c_stops_a_run_within_its_step(self):
        # Poses that never converge: without Ctrl-C the run would take hours.
        scene = fibremss.load_scene(
            "fusiform", {"stop": "iterations", "iterations": 1000000})
        timer = threading.Timer(1.0, os.kill, (os.getpid(), signal.SIGINT))
        start = time.monotonic()
        timer.start()
        with self.assertRaises(KeyboardInterrupt):
            fibremss.run(scene, threads=1)
        timer.join()
        self.assertLess(time.monotonic() - start, 30)

    def test_settings_are_read_and_set(self):
        scene = fibremss.load_scene("fusiform", SMALL)
        scene.integrator = "verlet"
        scene.gravity = (0, -9.81, 0)
        self.assertEqual(scene.integrator, "verlet")
        self.assertAlmostEqual(scene.gravity[1], -9.81, places=5)
        with self.assertRaises(fibremss.InputError):
            scene.integrator = "leapfrog"


class Errors(unittest.TestCase):
    def test_a_missing_scene_file_raises_input_error_naming_it(self):
        path = "/nonexistent/muscle.json"
        with self.assertRaises(fibremss.InputError) as caught:
            fibremss.load_scene(path)
        self.assertIsInstance(caught.exception, ValueError)
        self.assertEqual(caught.exception.source, path)
        self.assertIn(path, str(caught.exception))
        self.assertIn("nor a readable scene file", caught.exception.problem)

    def test_a_bad_field_names_the_file_the_field_and_what_was_expected(self):
        scene = json.loads(fibremss.export_scene("fusiform"))
        scene["simulation"]["iterations"] = "many"
        with tempfile.TemporaryDirectory() as out:
            path = os.path.join(out, "bad.json")
            with open(path, "w") as f:
                json.dump(scene, f)
            with self.assertRaises(fibremss.InputError) as caught:
                fibremss.load_scene(path)
        error = caught.exception
        self.assertEqual(error.source, path)
        self.assertIn("iterations", error.where)
        self.assertIn("expected", error.problem)
        self.assertEqual(str(error), f"{error.source}: {error.where}: {error.problem}")

    def test_a_bad_override_and_a_wrong_count_raise_input_error(self):
        with self.assertRaises(fibremss.InputError):
            fibremss.load_scene("fusiform", {"resolutoin": 8})
        simulation = fibremss.Simulation(fibremss.load_scene("fusiform", SMALL), threads=1)
        with self.assertRaises(fibremss.InputError):
            simulation.set_positions(0, np.zeros((3, 3)))
        with self.assertRaises(IndexError):
            simulation.positions(1)
        with self.assertRaises(KeyError):
            simulation.positions("biceps")


class Views(unittest.TestCase):
    def setUp(self):
        self.simulation = fibremss.Simulation(fibremss.load_scene("fusiform", SMALL), threads=1)

    def test_positions_are_a_read_only_view_of_the_solver_memory(self):
        first, again = self.simulation.positions(0), self.simulation.positions("fusiform")
        self.assertTrue(np.shares_memory(first, again))
        self.assertFalse(first.flags.owndata)
        self.assertFalse(first.flags.writeable)
        self.assertEqual(first.shape, (self.simulation.particle_count(0), 3))
        before = first.copy()
        self.simulation.set_pose(2)
        self.simulation.step()
        self.assertGreater(np.abs(first - before).max(), 1e-4)  # the view saw the step

    def test_a_view_keeps_its_simulation_alive(self):
        surface = self.simulation.surface(0)
        expected = surface.copy()
        del self.simulation
        gc.collect()
        np.testing.assert_array_equal(surface, expected)

    def test_other_arrays_are_views_too(self):
        s = self.simulation
        for view in (s.surface(0), s.rest_positions(0), s.radii(0), s.fixed_particles(0),
                     s.surface_triangles(0), s.residual_forces(0)):
            self.assertFalse(view.flags.owndata)
            self.assertFalse(view.flags.writeable)
        self.assertTrue(np.shares_memory(s.surface(0), s.surface(0)))
        self.assertEqual(s.surface_triangles(0).shape[1], 3)
        self.assertLess(s.surface_triangles(0).max(), len(s.surface(0)))

    def test_set_positions_moves_the_particles_and_the_surface(self):
        s = self.simulation
        surface = s.surface(0).copy()
        moved = s.positions(0) + np.array([0.001, 0, 0], dtype=s.positions(0).dtype)
        s.set_positions(0, moved)
        np.testing.assert_array_equal(s.positions(0), moved)
        np.testing.assert_allclose(s.surface(0) - surface, np.tile([0.001, 0, 0], (len(surface), 1)),
                                   atol=1e-5)


class Stepping(unittest.TestCase):
    def test_bone_transforms_round_trip_and_poses_move_bones(self):
        scene = fibremss.load_scene("fusiform", SMALL)
        s = fibremss.Simulation(scene, threads=1)
        s.set_pose(2)
        stats = s.step()
        self.assertEqual(stats["iterations"], scene.iterations)
        np.testing.assert_allclose(s.bone_transform("lower"), scene.bone_pose(1, 2), atol=1e-6)
        target = np.eye(4)
        target[:3, 3] = [0, -0.01, 0]
        s.set_bone_transform(1, target)
        s.step()
        np.testing.assert_allclose(s.bone_transform(1), target, atol=1e-6)
        self.assertAlmostEqual(s.time, 2 * stats["simulated_time_s"], places=6)

    def test_an_external_force_pushes_the_particles_its_way(self):
        scene = fibremss.load_scene("fusiform", SMALL)
        free = fibremss.Simulation(scene, threads=1)
        pushed = fibremss.Simulation(scene, threads=1)
        fixed = set(pushed.fixed_particles(0).tolist())
        particles = [i for i in range(pushed.particle_count(0)) if i not in fixed]
        pushed.set_external_forces(0, particles, np.tile([0.05, 0, 0], (len(particles), 1)))
        free.step()
        pushed.step()
        shift = (pushed.positions(0) - free.positions(0))[particles]
        self.assertGreater(shift[:, 0].mean(), 1e-5)
        pushed.clear_external_forces(0)
        self.assertGreater(pushed.force_residual()["rms_force_n"], 0)

    def test_a_duration_step_advances_exactly_that_time(self):
        scene = fibremss.load_scene("fusiform", SMALL)
        scene.integrator = "verlet"
        s = fibremss.Simulation(scene, threads=1)
        stats = s.step(0.005)
        self.assertAlmostEqual(stats["simulated_time_s"], 0.005, places=6)


class MatchesTheCommandLineTool(unittest.TestCase):
    """The module and `fibremss` give the same numbers for the same scene and settings."""

    def test_stepping_pose_by_pose_matches_run(self):
        scene = fibremss.load_scene("fusiform", SMALL)
        summary = fibremss.run(scene, threads=1)
        s = fibremss.Simulation(scene, threads=1)
        rows = []
        for pose in range(scene.pose_count):
            s.set_pose(pose)
            s.step()
            rows += s.measures()
        ours = fibremss.columns(rows)
        theirs = fibremss.columns(summary["series"])
        for key in ("volume_change_pct", "mean_fibre_length_mm", "max_fibre_stretch",
                    "residual_rms_mm", "time_s"):
            np.testing.assert_array_equal(ours[key], theirs[key], err_msg=key)

    @unittest.skipUnless(CLI, "FIBREMSS_CLI not set")
    def test_run_matches_the_cli_run(self):
        with tempfile.TemporaryDirectory() as out:
            run_cli("run", "fusiform", "--set", "resolution=8", "--threads", "1", "--out", out,
                    "--frame-every", "0")
            with open(os.path.join(out, "summary.json")) as f:
                cli = json.load(f)
        ours = fibremss.run(fibremss.load_scene("fusiform", SMALL), threads=1)
        for key in ("particles", "springs", "iterations", "steps", "volume_change_pct",
                    "spring_deviation_ratio", "max_penetration_mm"):
            self.assertEqual(ours[key], cli[key], key)
        self.assertEqual(ours["muscles"], cli["muscles"])
        self.assertEqual(fibremss.columns(ours["series"])["volume_change_pct"].tolist(),
                         fibremss.columns(cli["series"])["volume_change_pct"].tolist())

    @unittest.skipUnless(CLI, "FIBREMSS_CLI not set")
    def test_compare_matches_the_cli_compare_and_writes_its_files(self):
        with tempfile.TemporaryDirectory() as out:
            run_cli("compare", "fusiform", "--set", "resolution=8", "--threads", "1",
                    "--methods", "fibremss", "--no-fronts", "--no-reference",
                    "--out", os.path.join(out, "cli"))
            with open(os.path.join(out, "cli", "summary.json")) as f:
                cli = json.load(f)
            ours = fibremss.compare("fusiform", {"resolution": 8, "threads": 1},
                                    methods=["fibremss"], out_dir=os.path.join(out, "py"))
            self.assertTrue(os.path.exists(os.path.join(out, "py", "report.md")))
        run, cli_run = ours["runs"][-1], cli["runs"][-1]
        self.assertEqual(run["method"], "fibremss")
        for key in ("particles", "iterations", "volume_change_pct", "spring_deviation_ratio"):
            self.assertEqual(run[key], cli_run[key], key)


if __name__ == "__main__":
    unittest.main()
