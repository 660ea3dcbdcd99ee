"""The application layer: CLI, scenes, the frame loop and its drivers (window, capture, sweep,
bench). It wires ``lbm`` and ``raytrace``, which never import each other."""
