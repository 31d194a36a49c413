"""``python -m vehicle_emulator``: the ``vehicle-emu`` command (vehicle_emulator.fleet.cli)."""

import sys

from vehicle_emulator.fleet.cli import main

if __name__ == "__main__":
    sys.exit(main())
