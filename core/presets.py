"""Refractive-index profiles of the seed's mirage scenes, shared by tests, examples, add-on.

The seed's Figs. 10 and 11 show an inferior mirage (an inverted image below the object)
and Vince's phenomenon (an inverted ghost, and an upright one, above the object). Its
Eq. 17 and 18 are used with the literal Hamiltonian H = n |p|^2 / 2 (Eq. 8/16), whose n
is the physical index to the power -2. The seed's printed coefficients are not
available to us, so these are our reconstructions with the same phenomena, written in
that literal form (lengths in metres, the ground at z = 0):

- Eq. 17 (inferior mirage): hot ground; the physical index rises by 3e-3 within ~15 cm
  above it, n(z) = 1 + 0.003 (1 - exp(-z/0.15)).
- Eq. 18 (Vince's phenomenon): a warm inversion layer at 1.1 m; the physical index
  falls by 4e-3 across it, n(z) = 1 - 0.002 tanh((z - 1.1)/0.1).
"""

MIRAGE_EQ17_INDEX = "1/(1 + 0.003*(1 - exp(-z/0.15)))**2"
"""Literal-form n for the inferior mirage (seed Fig. 10)."""
MIRAGE_EQ18_INDEX = "1/(1 - 0.002*tanh((z - 1.1)/0.1))**2"
"""Literal-form n for Vince's phenomenon, a ghost above the object (seed Fig. 11)."""
