"""matplotlib, set up once for files: the non-interactive Agg backend, chosen before
pyplot is first imported, so figures render on machines without a display.
Every figure module of acslam imports ``plt`` from here."""

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

__all__ = ["plt"]
