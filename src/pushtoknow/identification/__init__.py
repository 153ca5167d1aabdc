"""Physics-based identification: fit φ = (m, μ, c_x, c_y, I_z) by replaying recorded pushes in
the testbed's own MuJoCo scene (README, "Physics-based identification").

Pure library: `identify` takes recorded pushes and a footprint and returns an
`Identification` (SI estimates with Laplace-and-prior uncertainty); `recordings` reads them
from the project's dataset format. The CLI (`pushtoknow identify`) only parses and prints.
"""
