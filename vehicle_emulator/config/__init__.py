"""What each emulated vehicle is, as the team file and the personality say: its
personality (protocol face, inner-loop and sensor models), parameter table, spec and faults.
Every other room reads these; they read none of the others."""
