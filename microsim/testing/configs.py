"""Small configs that several test files share, as TOML text (what ``microsim run`` reads).

Contract: each traces in a second or two at most and has a fixed seed; a test derives what it
needs from one (``str.replace`` of a line it names). ``SPHERES``: small Boolean spheres, two
incidences; ``SWEEP_BASE``: smaller spheres, the base of the sweep tests, and ``GRID`` its grid
sweep of 6 points. :mod:`microsim.testing.interruptions` derives its resumable run from SPHERES.
"""

#: Boolean spheres at phi = 0.3 on a tile of 16, two incidences, 20 000 paths (the command line's tests)
SPHERES = """
name = "small"
[scene]
kind = "poisson_spheres"
volume_fraction = 0.3
tile = 16.0
depth = 8.0
[material]
kind = "lambert"
albedo = 0.8
[illumination]
theta_i_deg = [0.0, 60.0]
[sensor]
cells = 200
[run]
paths = 20_000
realizations = 4
seed = 5
"""
#: sparser spheres on a smaller tile, 400 paths (the sweep tests' base)
SWEEP_BASE = """[scene]
kind = "poisson_spheres"
volume_fraction = 0.2
tile = 8.0
depth = 8.0
[material]
kind = "lambert"
albedo = 0.8
[illumination]
theta_i_deg = [0.0, 60.0]
[sensor]
cells = 50
[run]
paths = 400
realizations = 2
seed = 3
"""
GRID = SWEEP_BASE + """[sweep]
"scene.volume_fraction" = [0.1, 0.3]
"material.albedo" = [0.5, 0.7, 0.9]
"""
