"""Where the tests find the repository's files and the shared real data, wherever a test lives."""

from pathlib import Path

#: the checkout under test (holds pmdcid/, fixtures/, docs/, bench/)
REPO = Path(__file__).resolve().parents[1]
FIXTURES = REPO / "fixtures"
#: the real measured logs, beside the checkout (never copied into it)
REAL = REPO.parent / "shared" / "data" / "real"
