"""pmdcid: non-linear identification of permanent-magnet DC motors from measured logs.

Import order (one way): io -> model -> simulate -> identify -> diagnose -> report -> cli.
"""

__version__ = "0.1.0"
