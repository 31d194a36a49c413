"""MAVSDK's takeoff_and_land example, started the moment a fresh ``vehicle-emu --id 1`` (px4
personality) prints its ready line, N times in a row: how often a stock client's first flight
works.

The steps are the MAVSDK-Python example's (examples/takeoff_and_land.py), on mavsdk 4.x's asyncio
API: connect, wait until connected, wait for health ``is_global_position_ok`` and
``is_home_position_ok``, arm, takeoff, sleep 10 s, land. Nothing is retried. Besides, the script
records (without acting on it) when each step happened and the highest altitude reached.

    python -m benchmarks.bench_mavsdk_takeoff_land --starts 10
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import sys
import tempfile
import time

from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
from mavsdk.plugins.action import ActionError

from tests.harness import free_udp_port, run_emulator_ready

EXAMPLE_SLEEP_S = 10.0  # the example's asyncio.sleep(10) between takeoff and land


async def takeoff_and_land(port: int, step_timeout_s: float = 30.0) -> dict:
    """The example's steps against a vehicle sending to 127.0.0.1:``port``. Returns the times
    [s from the call] of each step, ``arm_error`` (the ActionError's text, or None), the highest
    relative altitude [m] seen and the land result."""
    t0 = time.monotonic()
    out: dict = {"arm_error": None, "max_rel_alt_m": 0.0, "texts": []}
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as mavsdk:
        await mavsdk.add_any_connection(f"udpin://127.0.0.1:{port}")
        system = await mavsdk.first_autopilot(timeout_s=step_timeout_s)
        assert system is not None, "MAVSDK found no autopilot"
        telemetry, action = TelemetryAsync(system), ActionAsync(system)

        async def watch_texts() -> None:
            async for text in telemetry.subscribe_status_text():
                out["texts"].append((round(time.monotonic() - t0, 3), text.text))

        async def watch_altitude() -> None:
            async for pos in telemetry.subscribe_position():
                out["max_rel_alt_m"] = max(out["max_rel_alt_m"], pos.relative_altitude_m)

        watchers = [asyncio.create_task(watch_texts()), asyncio.create_task(watch_altitude())]
        try:
            async def connected() -> None:
                async for state in system.is_connected_state():
                    if state:
                        return
            if not await system.is_connected():
                await asyncio.wait_for(connected(), step_timeout_s)
            out["connected_s"] = time.monotonic() - t0

            async def healthy() -> None:
                async for health in telemetry.subscribe_health():
                    if health.is_global_position_ok and health.is_home_position_ok:
                        return
            await asyncio.wait_for(healthy(), step_timeout_s)
            out["health_ok_s"] = time.monotonic() - t0
            try:
                await action.arm()
            except ActionError as err:
                out["arm_error"] = str(err)
                return out
            out["armed_s"] = time.monotonic() - t0
            await action.takeoff()
            out["takeoff_s"] = time.monotonic() - t0
            await asyncio.sleep(EXAMPLE_SLEEP_S)
            await action.land()
            out["land_s"] = time.monotonic() - t0
        finally:
            for task in watchers:
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await task
    return out


def one_start(log_dir: str) -> dict:
    """A fresh emulator; the example starts the moment it prints ready."""
    port = free_udp_port()
    with run_emulator_ready(["--id", "1"], remote_port=port, log_dir=log_dir):
        return asyncio.run(takeoff_and_land(port))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--starts", type=int, default=10)
    args = parser.parse_args()
    passed = 0
    with tempfile.TemporaryDirectory() as log_dir:
        for k in range(args.starts):
            r = one_start(log_dir)
            ok = r["arm_error"] is None and "land_s" in r and r["max_rel_alt_m"] > 2.0
            passed += ok
            print(f"start {k + 1}: {'ok' if ok else 'FAILED'}  health ok {r['health_ok_s']:.2f} s"
                  f"  arm {r.get('armed_s', float('nan')):.2f} s  max alt "
                  f"{r['max_rel_alt_m']:.2f} m  arm error {r['arm_error']}", flush=True)
    print(f"{passed} of {args.starts} starts flew takeoff_and_land")
    return 0 if passed == args.starts else 1


if __name__ == "__main__":
    sys.exit(main())
