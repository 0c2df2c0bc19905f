"""Bytes an ensemble moves between processes, before and after the Collect hooks: 100
Henon-Heiles orbits on the section q1 = 0 at E = 1/8 to t = T, their whole solutions against
their crossings only (pickle sizes of what the workers return), CPU beside wall time, load."""

import os
import pickle
import sys
import time

from ddvp_nlp import load_scene
from ddvp_nlp.io import machine
from ddvp_nlp.solvers import Collect, march_ensemble
from ddvp_nlp.studies import SectionOutput, section_starts


def main(t_end: float = 5000.0, orbits: int = 100, workers: int = 2) -> None:
    system = load_scene("henon_heiles").system
    theta = system.parameter_vector(None)
    starts = section_starts(system, theta, 0.125, "q1=0", orbits)
    n = system.n
    print(f"load average {os.getloadavg()}; {orbits} orbits to t = {t_end:g}, {workers} workers")
    results = {}
    for label, collect in (("whole solutions", None),
                           ("crossings only", Collect(output=SectionOutput(0, 0.0, "+", 0.125)))):
        wall, cpu = time.perf_counter(), time.process_time()
        out = march_ensemble(system, starts[:, :n], starts[:, n:], (0.0, t_end), tau0=0.05,
                             workers=workers, collect=collect)
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        size = len(pickle.dumps(out, protocol=pickle.HIGHEST_PROTOCOL))
        results[label] = out
        print(f"{label:16s}: {size / 1e6:10.3f} MB returned, wall {wall:.2f} s, "
              f"CPU (this process) {cpu:.2f} s")
    crossings = sum(o["times"].size for o in results["crossings only"])
    print(f"crossings: {crossings}")
    print(f"machine: {machine()}")


if __name__ == "__main__":
    main(*(float(a) for a in sys.argv[1:2]))
