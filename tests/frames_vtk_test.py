#!/usr/bin/python3
"""Frames of `fibremss run` read back by real clients: VTK 9's vtkXMLPolyDataReader and
ParaView 5.11's PVD reader (Debian's python3-paraview, which brings its VTK 9 along); the
glTF frames (--format gltf) by VTK's vtkGLTFReader.

Usage: frames_vtk_test.py FIBREMSS SOURCE_DIR WORK_DIR. Exits 77 (ctest: skipped) with a message
when the Python modules are not installed."""
import math
import os
import shutil
import subprocess
import sys

try:
    from vtkmodules.vtkIOXML import vtkXMLPolyDataReader
    from vtkmodules.vtkIOGeometry import vtkGLTFReader
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkCommonCore import vtkVersion
    import paraview.simple as pvs
    from paraview import servermanager
except ImportError as error:
    print(f"SKIPPED: VTK 9 / ParaView Python modules not found ({error}); install Debian's "
          "python3-paraview (./setup.sh test does) and run with /usr/bin/python3")
    sys.exit(77)

failures = []


def check(condition, what):
    if not condition:
        failures.append(what)
        print("FAILED:", what)


def read_vtp(path):
    reader = vtkXMLPolyDataReader()
    reader.SetFileName(path)
    reader.Update()
    check(reader.GetErrorCode() == 0, f"{path}: VTK reports error {reader.GetErrorCode()}")
    return reader.GetOutput()


def point_arrays(data):
    arrays = data.GetPointData()
    return {arrays.GetArrayName(i): vtk_to_numpy(arrays.GetArray(i))
            for i in range(arrays.GetNumberOfArrays())}


def field(data, name):
    array = data.GetFieldData().GetAbstractArray(name)
    return None if array is None else vtk_to_numpy(array)


def main():
    fibremss, source, work = sys.argv[1:4]
    shutil.rmtree(work, ignore_errors=True)
    scene = os.path.join(source, "scenes", "json", "example-elbow.json")  # millimetres
    steps = 3
    # max_step_deg=0: the sweep's 10° poses as given, no 5° sub-poses between them.
    subprocess.run([fibremss, "run", scene, "--set", "resolution=12", "--set", "max_step_deg=0",
                    "--steps", str(steps),
                    "--frame-every", "1", "--format", "vtk,gltf", "--out", work], check=True,
                   stdout=subprocess.DEVNULL)
    print("VTK", vtkVersion.GetVTKVersion())
    frames = os.path.join(work, "frames")

    # VTK: every muscle file has every array, in millimetres, with the pose in its field data.
    expected_muscle = {"displacement": 3, "fibre_stretch": 1, "spring_strain": 1, "muscle_id": 1,
                       "fixed": 1}
    labels = []
    for step in range(steps):
        surface = read_vtp(os.path.join(frames, f"muscle0_flexor_surface_{step:05d}.vtp"))
        particles = read_vtp(os.path.join(frames, f"muscle0_flexor_particles_{step:05d}.vtp"))
        check(surface.GetNumberOfPoints() > 100 and surface.GetNumberOfPolys() > 100,
              f"step {step}: surface has {surface.GetNumberOfPoints()} points")
        check(particles.GetNumberOfLines() > 0 and particles.GetNumberOfVerts() ==
              particles.GetNumberOfPoints(), f"step {step}: particles lack fibres or vertices")
        for data, extra in ((surface, {"penetration": 1}), (particles, {"radius": 1})):
            arrays = point_arrays(data)
            for name, components in {**expected_muscle, **extra}.items():
                check(name in arrays, f"step {step}: array {name} missing ({sorted(arrays)})")
                if name not in arrays:
                    continue
                values = arrays[name]
                shape = values.shape[1] if values.ndim == 2 else 1
                check(shape == components, f"{name}: {shape} components")
                check(len(values) == data.GetNumberOfPoints(), f"{name}: {len(values)} tuples")
                check(bool((values == values).all()), f"{name} has NaN")
            check((arrays["muscle_id"] == 0).all(), "muscle_id of the only muscle is 0")
            check(set(arrays["fixed"].tolist()) <= {0.0, 1.0} or data is surface,
                  "particles' fixed is 0 or 1")
            check(arrays["fixed"].max() > 0, "some particles are fixed")
            check(0.5 < arrays["fibre_stretch"].min() <= arrays["fibre_stretch"].max() < 2,
                  f"fibre stretch {arrays['fibre_stretch'].min()}..{arrays['fibre_stretch'].max()}")
        check((point_arrays(surface)["penetration"] >= 0).all(), "penetration >= 0")
        # The flexor spans y from -110 to 220 mm: in metres it would be 1000x smaller.
        bounds = surface.GetBounds()
        check(200 < bounds[3] < 240 and -130 < bounds[2] < -60,
              f"step {step}: surface y bounds {bounds[2:4]} are not the scene's millimetres")
        check(abs(field(surface, "step")[0] - step) == 0, "field data step")
        labels.append(float(field(surface, "pose_label")[0]))
        time = float(field(surface, "TimeValue")[0])
        check(time > 0 and math.isfinite(time), f"TimeValue {time}")
    check(labels == [0.0, 10.0, 20.0], f"pose labels {labels} (the sweep's angles 0, 10, 20)")

    # A still bone is written once; the moving one each frame, with its transform.
    check(sorted(f for f in os.listdir(frames) if f.startswith("bone0")) ==
          ["bone0_upper-arm_00000.vtp"], "the upper arm (still) is written once")
    forearm = sorted(f for f in os.listdir(frames) if f.startswith("bone1"))
    check(len(forearm) == steps, f"the forearm (moving) is written every frame: {forearm}")
    upper = read_vtp(os.path.join(frames, "bone0_upper-arm_00000.vtp"))
    check(300 < upper.GetBounds()[3] < 330, f"upper arm y bounds {upper.GetBounds()[2:4]} in mm")
    transform = field(read_vtp(os.path.join(frames, forearm[-1])), "transform").reshape(4, 4)
    check(abs(transform[1][1] - math.cos(math.radians(20))) < 1e-6, f"transform {transform}")

    # ParaView: the .pvd's times are increasing simulated seconds; every part loads at each.
    reader = pvs.PVDReader(FileName=os.path.join(work, "run.pvd"))
    times = list(reader.TimestepValues)
    print("ParaView", servermanager.vtkSMProxyManager.GetParaViewSourceVersion(), "times", times)
    check(len(times) == steps and all(b > a > 0 for a, b in zip(times, times[1:])),
          f"ParaView times {times}")
    names = set(reader.PointData.keys())
    for name in list(expected_muscle) + ["penetration"]:
        check(name in names, f"ParaView lists no point array {name} ({sorted(names)})")
    for time in times:
        reader.UpdatePipeline(time)
        blocks = servermanager.Fetch(reader)
        check(blocks.GetNumberOfBlocks() == 4, f"{blocks.GetNumberOfBlocks()} parts at t={time}")
        # ParaView lists each part by the name run.pvd gives it.
        block_names = [blocks.GetMetaData(b).Get(blocks.NAME())
                       for b in range(blocks.GetNumberOfBlocks())]
        check(block_names == ["flexor surface", "flexor particles", "upper-arm", "forearm"],
              f"block names {block_names}")
        for b in range(blocks.GetNumberOfBlocks()):
            block = blocks.GetBlock(b)
            check(block is not None and block.GetNumberOfPoints() > 0, f"part {b} at t={time}")

    # glTF: each frame's .glb holds the muscle and both bones; the muscle's vertices are the
    # surface frame's, in metres (glTF's unit) where the .vtp has millimetres.
    for step in range(steps):
        gltf = vtkGLTFReader()
        gltf.SetFileName(os.path.join(work, "gltf", f"frame_{step:05d}.glb"))
        gltf.Update()
        meshes = []
        it = gltf.GetOutput().NewIterator()
        it.InitTraversal()
        while not it.IsDoneWithTraversal():
            meshes.append(it.GetCurrentDataObject())
            it.GoToNextItem()
        check(len(meshes) == 3, f"step {step}: {len(meshes)} glTF meshes, expected 3")
        surface = read_vtp(os.path.join(frames, f"muscle0_flexor_surface_{step:05d}.vtp"))
        muscle = [m for m in meshes if m.GetNumberOfPoints() == surface.GetNumberOfPoints()]
        check(len(muscle) == 1, f"step {step}: no glTF mesh with the surface's vertex count")
        if muscle:
            error = abs(1000 * vtk_to_numpy(muscle[0].GetPoints().GetData()) -
                        vtk_to_numpy(surface.GetPoints().GetData())).max()
            check(error < 1e-3, f"step {step}: glTF vertices {error} mm off the surface frame's")

    if failures:
        print(f"{len(failures)} check(s) failed")
        sys.exit(1)
    print("frames read by VTK and ParaView: all checks passed")


main()
