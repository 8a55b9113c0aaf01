"""Times VTK reading a run's frames: every `frames/frame_NNNN.vtu` with
vtkXMLUnstructuredGridReader against every step of `frames.vtkhdf` with
vtkHDFReader (the readers ParaView uses). Needs the `vtk` wheel.

    python3 benches/vtk_read.py OUTPUT_DIR [REPEATS]
"""
import glob
import sys
import time

from vtkmodules.vtkCommonExecutionModel import vtkStreamingDemandDrivenPipeline
from vtkmodules.vtkIOHDF import vtkHDFReader
from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader

out = sys.argv[1]
repeats = int(sys.argv[2]) if len(sys.argv) > 2 else 2
vtus = sorted(glob.glob(out + "/frames/frame_*.vtu"))


def vtu(paths):
    for path in paths:
        r = vtkXMLUnstructuredGridReader()
        r.SetFileName(path)
        r.Update()


def vtkhdf(first_only):
    r = vtkHDFReader()
    r.SetFileName(out + "/frames.vtkhdf")
    if first_only:
        r.Update()
        return
    r.UpdateInformation()
    times = r.GetOutputInformation(0).Get(vtkStreamingDemandDrivenPipeline.TIME_STEPS())
    assert len(times) == len(vtus), (len(times), len(vtus))
    for t in times:
        r.UpdateTimeStep(t)


cases = [
    ("first frame, VTU", lambda: vtu(vtus[:1])),
    ("first frame, VTKHDF", lambda: vtkhdf(True)),
    (f"all {len(vtus)} frames, VTU", lambda: vtu(vtus)),
    (f"all {len(vtus)} frames, VTKHDF", lambda: vtkhdf(False)),
]
for rep in range(repeats):
    for name, run in cases:
        start = time.perf_counter()
        run()
        print(f"repeat {rep}: {name}: {time.perf_counter() - start:.3f} s")
