"""Closed-form and series solutions the verification holds the program to (tests/ and the
accuracy studies in workflows/): none of the program's modules imports them.

- `scattering`: Pao & Mow's series for plane SV scattered by an unlined or a lined circular cavity;
- `lined_tunnel`: a circular tunnel with a bonded lining excavated in stages (Kirsch's unlined
  solution is its first stage);
- `elliptical_opening`: an elliptical opening under a far-field stress (Muskhelishvili);
- `salencon`: Salencon's circular cavity in a Mohr-Coulomb medium, and the static stage's fields
  in its conventions.
"""
