"""pytest set-up shared by the test suite and the doctests of the package (run from the repository root)."""

import matplotlib

matplotlib.use("Agg")
