"""Closed-form solutions to measure against: Hertz line contact with McEwen's subsurface field,
and the exact fields a scene may declare (``[exact]``: uniform or Hertz)."""

from .exact import exact_field, exact_reference
from .hertz import HertzData, hertz_line_contact, hertz_pressure, mcewen_stress

__all__ = ["HertzData", "exact_field", "exact_reference", "hertz_line_contact", "hertz_pressure", "mcewen_stress"]
