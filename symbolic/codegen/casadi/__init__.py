"""The CasADi backend: printer (:mod:`.printer`) and emitter (:mod:`.emitter`)."""

from gearsym.symbolic.codegen.casadi.emitter import (
    CasadiFunctionView,
    CasadiModuleView,
    emit_casadi_files,
)
from gearsym.symbolic.codegen.casadi.printer import CasadiPrinter

__all__ = ["CasadiFunctionView", "CasadiModuleView", "CasadiPrinter", "emit_casadi_files"]
