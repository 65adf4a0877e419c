# ft_sitl first, before anything loads numpy: its import pins the BLAS settings trial
# results depend on (ft_sitl.numeric_env), so trials flown in this process match those of
# the ft-sitl command and the committed results
import ft_sitl  # noqa: F401, I001

import os
from pathlib import Path

import pytest

# The team's shared material (the paper's tables, the NavRL checkpoint) sits beside the
# repository as ../shared; FT_SITL_SHARED points a clone elsewhere at it.
SHARED_ENV = "FT_SITL_SHARED"
SHARED = Path(os.environ.get(SHARED_ENV) or Path(__file__).resolve().parents[1].parent / "shared")
TABLE1 = SHARED / "spec" / "platforms_table1.csv"


@pytest.fixture(scope="session")
def table1_rows():
    """The paper's Table 1, as shipped in shared/spec (the source the catalog was built from)."""
    import csv

    if not TABLE1.exists():
        pytest.fail(f"{TABLE1} is missing: the tests check the catalog against the paper's "
                    f"table (set {SHARED_ENV} to the directory holding spec/)")
    with open(TABLE1, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


NAVRL_CHECKPOINT = SHARED / "data" / "navrl" / "navrl_checkpoint.pt"


@pytest.fixture(scope="session")
def navrl_checkpoint() -> Path:
    """The NavRL authors' released checkpoint, as test data (ft-sitl does not ship it)."""
    if not NAVRL_CHECKPOINT.is_file():
        pytest.fail(f"{NAVRL_CHECKPOINT} is missing: the NavRL tests read the released "
                    f"checkpoint from the team's shared data (set {SHARED_ENV} to the directory "
                    "holding data/navrl/)")
    return NAVRL_CHECKPOINT
