"""Branch codes of the plastic return mappings Z(Sigma, h) (the same integers in C++ and Python;
they are part of the test-vector format and must not be renumbered)."""

ELASTIC = 0  # inside the elastic region: Z = Sigma_c
APEX = 1  # Drucker-Prager, tr(eps) > 0: stress-free, Z = 1
CONE = 2  # Drucker-Prager, projected onto the cone
COMPRESSION_TIP = 3  # Cam-Clay, p > p0
TENSION_TIP = 4  # Cam-Clay, p < -beta p0
ELLIPSE = 5  # Cam-Clay, projected onto the ellipse at fixed p
YIELD = 6  # von Mises, projected along the volume-preserving path

#: BRANCH_NAMES[code] is the name used in the test vectors.
BRANCH_NAMES = ("elastic", "apex", "cone", "compression_tip", "tension_tip", "ellipse", "yield")
