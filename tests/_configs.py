"""TOML run configurations shared by the CLI and bad-input tests."""

# A 2-bins-per-decade, 10-yr growth run at 1 AU (seconds to run): the smallest configuration
# that exercises the whole `jaxcoag run` path.
SMALL = """
[run]
name = "small_growth"
[gas]
model = "mmsn_hayashi81"
R_au = 1.0
alpha = 1e-3
[dust]
rho_s = 1.6
a0 = 1e-4
[grid]
m_max = 1e-6
bins_per_decade = 2
[solver]
rtol = 1e-4
[time]
t_end_yr = 10.0
n_out = 3
"""

# The same physics with the grouped Monte Carlo engine (distribution grouping, 40 groups): a few
# seconds, for the common-layout, resume and CLI tests of the Monte Carlo path.
SMALL_MC = SMALL.replace('name = "small_growth"\n', 'name = "small_growth_mc"\nengine = "mc"\n') + """
[mc]
seed = 3
grouping = "distribution"
ns_target = 40
n_particles = 1e20
"""
