"""MuJoCo pushing testbed ("Sim-Robotac"): objects, scene, pusher, tactile pad, RGB-D camera."""
