"""Isotropic linear-elastic materials (SI units).

Lamé parameters: λ = Eν/((1+ν)(1−2ν)), μ = G = E/(2(1+ν)); stress σ = λ tr(ε) I + 2μ ε.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from userio.errors import InputError


@dataclass(frozen=True)
class Material:
    """Isotropic material: Young's modulus E (Pa), Poisson ratio ν, yield strength (Pa)."""

    E_Pa: float
    nu: float
    yield_Pa: float = math.nan
    name: str = "material"

    def __post_init__(self):
        if not (math.isfinite(self.E_Pa) and self.E_Pa > 0):
            raise InputError(f"material {self.name!r}: field E_Pa must be > 0, got {self.E_Pa}")
        if not (-1.0 < self.nu < 0.5):
            raise InputError(f"material {self.name!r}: field nu must be in (-1, 0.5), got {self.nu}")
        if not (math.isnan(self.yield_Pa) or self.yield_Pa > 0):
            raise InputError(f"material {self.name!r}: field yield_Pa must be > 0, got {self.yield_Pa}")

    @property
    def lame_lambda_Pa(self) -> float:
        """λ = Eν/((1+ν)(1−2ν))."""
        return self.E_Pa * self.nu / ((1 + self.nu) * (1 - 2 * self.nu))

    @property
    def shear_modulus_Pa(self) -> float:
        """μ = G = E/(2(1+ν))."""
        return self.E_Pa / (2 * (1 + self.nu))

    @property
    def bulk_modulus_Pa(self) -> float:
        """K = E/(3(1−2ν))."""
        return self.E_Pa / (3 * (1 - 2 * self.nu))

    def with_(self, **changes) -> "Material":
        """Copy with some fields changed."""
        from dataclasses import replace

        return replace(self, **changes)


ALUMINIUM_6061_T6 = Material(E_Pa=68.9e9, nu=0.33, yield_Pa=276e6, name="aluminium 6061-T6")
STEEL = Material(E_Pa=200e9, nu=0.29, yield_Pa=250e6, name="structural steel")
