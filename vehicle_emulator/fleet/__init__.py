"""A fleet of emulated vehicles as one program: the runner's loop, the team file, faults,
the ``vehicle-emu`` command."""
