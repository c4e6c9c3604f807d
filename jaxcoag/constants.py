"""Physical constants in cgs units.

CODATA 2018 / IAU 2015 nominal values (the set used for the reference values in the tests).
"""

k_B = 1.380649e-16  # Boltzmann constant [erg K^-1] (CODATA 2018, exact)
m_H = 1.6735575e-24  # hydrogen atom mass [g]
G = 6.67430e-8  # gravitational constant [cm^3 g^-1 s^-2] (CODATA 2018)
M_sun = 1.98847e33  # solar mass [g]
AU = 1.495978707e13  # astronomical unit [cm] (IAU 2012, exact)
yr = 3.15576e7  # Julian year [s]
pc = 3.0856775814913673e18  # parsec [cm]
km = 1.0e5  # kilometre [cm]

mu_gas = 2.34  # mean molecular weight of H2/He gas (Ormel 2008, List of Symbols / ch. 6)
sigma_mol = 2.0e-15  # molecular collision cross-section [cm^2] (Ormel 2008 ch. 1, below eq. 1.17)
