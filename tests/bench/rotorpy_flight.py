#!/usr/bin/env python3
"""Time RotorPy on the flight `make bench` times propid_sitl on (benchmark only).

    rotorpy_flight.py [--duration S] [--sim-rate HZ]

RotorPy's Crazyflie with its SE(3) controller on a planar Lissajous for
--duration simulated seconds (default 10) at --sim-rate steps per second
(default 500 = propid_sitl's control rate; RotorPy integrates each step with
scipy's adaptive solver), default IMU and motion-capture sensors, no plots.
Prints one JSON object: rotorpy version, simulated seconds, process CPU time
of the run and the real-time factor (simulated / CPU seconds). Runs in the
bench-only virtual environment that `make bench` creates.
"""

import argparse
import json
import time


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=10.0, help="simulated seconds (10)")
    parser.add_argument("--sim-rate", type=float, default=500.0, help="steps per second (500)")
    args = parser.parse_args()

    from importlib.metadata import version

    import numpy as np
    from rotorpy.controllers.quadrotor_control import SE3Control
    from rotorpy.environments import Environment
    from rotorpy.trajectories.lissajous_traj import TwoDLissajous
    from rotorpy.vehicles.crazyflie_params import quad_params
    from rotorpy.vehicles.multirotor import Multirotor

    # The slow part of propid_sitl's Lissajous: 0.6 m x 0.5 m, 1 and 2 cycles per 10 s.
    trajectory = TwoDLissajous(A=0.6, B=0.5, a=2 * np.pi / 10.0, b=2 * 2 * np.pi / 10.0,
                               height=1.0)
    vehicle = Multirotor(quad_params)
    start = trajectory.update(0.0)
    vehicle.initial_state["x"] = np.array(start["x"], dtype=float)
    sim = Environment(vehicle=vehicle, controller=SE3Control(quad_params), trajectory=trajectory,
                      sim_rate=args.sim_rate)
    sim.vehicle.initial_state = vehicle.initial_state
    cpu0 = time.process_time()
    sim.run(t_final=args.duration, use_mocap=False, terminate=False, plot=False,
            animate_bool=False, verbose=False)
    cpu = time.process_time() - cpu0
    print(json.dumps({"rotorpy_version": version("rotorpy"), "simulated_s": args.duration,
                      "sim_rate_hz": args.sim_rate, "cpu_s": cpu,
                      "realtime_factor": args.duration / cpu}))


if __name__ == "__main__":
    main()
