"""Interactive and presentation tools: viewer, teleoperation, demonstrations, renders."""
