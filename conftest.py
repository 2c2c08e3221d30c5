"""pytest set-up shared by the test suite and the package's doctests (run from the root)."""

import matplotlib

matplotlib.use("Agg")
