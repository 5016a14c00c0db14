"""The one place that imports PyElastica's internal rod kernels (not its public API), behind a version
guard: a PyElastica without them stops with one line naming the installed and supported versions.
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

SUPPORTED = ">=1.0,<2"  # as pyproject.toml's dependency


class PyElasticaVersionError(ImportError):
    """The installed PyElastica lacks the internal kernels the Cosserat plant uses."""


def _installed() -> str:
    try:
        return version("pyelastica")
    except PackageNotFoundError:
        return "not installed"


try:
    from elastica._linalg import _batch_cross, _batch_matvec
    from elastica._rotations import _inv_rotate
    from elastica.rod.cosserat_rod import (
        _compute_bending_twist_strains,
        _compute_dilatation_rate,
        _compute_shear_stretch_strains,
        _update_accelerations,
    )
    from elastica.rod.data_structures import overload_operator_kinematic_numba
except (ImportError, AttributeError) as exc:
    raise PyElasticaVersionError(
        f"the Cosserat plant needs PyElastica's internal rod kernels ({exc}): installed pyelastica "
        f"{_installed()}, supported pyelastica{SUPPORTED}") from None

__all__ = ["SUPPORTED", "PyElasticaVersionError", "_batch_cross", "_batch_matvec",
           "_compute_bending_twist_strains", "_compute_dilatation_rate", "_compute_shear_stretch_strains",
           "_inv_rotate", "_update_accelerations", "overload_operator_kinematic_numba"]
