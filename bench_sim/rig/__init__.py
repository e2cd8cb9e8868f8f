"""rig stage."""
