#!/usr/bin/python3
"""LinuxCNC "display" for tests/controllers/test_linuxcnc_motion.py: run by the `linuxcnc`
script as `linuxcnc_display.py -ini INI` (the [DISPLAY] DISPLAY of the test's INI) under
Debian's /usr/bin/python3, which has LinuxCNC's `linuxcnc` and `hal` modules (the venv has not).

It takes the machine out of estop, homes all joints in place, and for each target of the job
(JSON file named by $STATION_LC_JOB) approaches it from below and from above with G0 moves
(all joints together), waits until motion is done and motmod's rate-limited trim has settled,
and reads the joints' HAL pins as doubles (`hal.get_value`; `halcmd getp` prints only 7
significant digits). It writes the readings to the job's `out` file and exits; the `linuxcnc`
script then shuts everything down. Any failure is written to `out` as {"error": ...}.
"""

import json
import os
import sys
import time
import traceback

import hal
import linuxcnc

AXES = "XYZUVW"


def main() -> None:
    job = json.load(open(os.environ["STATION_LC_JOB"]))
    out = job["out"]
    try:
        result = run(job)
    except Exception:
        result = {"error": traceback.format_exc()}
    tmp = out + ".tmp"
    with open(tmp, "w") as fh:
        json.dump(result, fh)
    os.replace(tmp, out)


def run(job: dict) -> dict:
    joints = int(job["joints"])
    overrun = float(job["overrun_mm"])
    comp = hal.component("station_probe")  # hal.get_value needs a component of this process
    comp.ready()
    cmd, stat, err = linuxcnc.command(), linuxcnc.stat(), linuxcnc.error_channel()
    messages = []

    def drain_errors():
        while True:
            e = err.poll()
            if not e:
                return
            messages.append(str(e[1]))

    def wait(pred, what, timeout_s=20.0):
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            stat.poll()
            if pred():
                return
            time.sleep(0.005)
        drain_errors()
        raise RuntimeError(f"timed out waiting for {what}; LinuxCNC said: {messages}")

    wait(lambda: True, "status")
    cmd.state(linuxcnc.STATE_ESTOP_RESET)
    cmd.state(linuxcnc.STATE_ON)
    wait(lambda: stat.task_state == linuxcnc.STATE_ON, "machine on")
    cmd.home(-1)
    wait(lambda: all(stat.homed[:joints]), "homing")
    cmd.mode(linuxcnc.MODE_MDI)
    cmd.wait_complete()

    def pin(name):
        return float(hal.get_value(name))

    def move_to(x):
        words = " ".join(f"{AXES[j]}{x:.6f}" for j in range(joints))
        cmd.mdi(f"G90 G0 {words}")
        cmd.wait_complete(30.0)
        # wait_complete can return before the motion ends (and stat may still show the last
        # move's end): wait until every joint's command is at the target and at rest
        wait(lambda: stat.state == linuxcnc.RCS_DONE and stat.inpos and all(
            abs(pin(f"joint.{j}.pos-cmd") - x) < 1e-9 and pin(f"joint.{j}.vel-cmd") == 0.0 for j in range(joints)),
             f"move to {x}")

    def settled():
        # the trim motmod commands (backlash-filt) ramps to the target trim (backlash-corr)
        end = time.monotonic() + 5.0
        while time.monotonic() < end:
            if all(pin(f"joint.{j}.backlash-filt") == pin(f"joint.{j}.backlash-corr") for j in range(joints)):
                return
            time.sleep(0.002)
        raise RuntimeError("the trim did not settle within 5 s: " + ", ".join(
            f"joint {j}: corr {pin(f'joint.{j}.backlash-corr')!r} filt {pin(f'joint.{j}.backlash-filt')!r} "
            f"vel {pin(f'joint.{j}.backlash-vel')!r}" for j in range(joints))
            + f" rapidrate {stat.rapidrate} feedrate {stat.feedrate} adaptive {pin('motion.adaptive-feed')}"
            + f" hold {hal.get_value('motion.feed-hold')} inhibit {hal.get_value('motion.feed-inhibit')} enables {stat.enabled}")

    readings = []
    for x in job["targets_mm"]:
        for direction in (1, -1):
            move_to(x - direction * overrun)
            move_to(x)
            settled()
            for j in range(joints):
                readings.append({
                    "target_mm": x, "direction": direction, "joint": j,
                    "pos_cmd_mm": pin(f"joint.{j}.pos-cmd"),
                    "backlash_corr_mm": pin(f"joint.{j}.backlash-corr"),
                    "backlash_filt_mm": pin(f"joint.{j}.backlash-filt"),
                    "motor_pos_cmd_mm": pin(f"joint.{j}.motor-pos-cmd"),
                    "motor_offset_mm": pin(f"joint.{j}.motor-offset"),
                })
    drain_errors()
    return {"readings": readings, "messages": messages, "version": getattr(linuxcnc, "version", "?")}


if __name__ == "__main__":
    main()
    sys.exit(0)
