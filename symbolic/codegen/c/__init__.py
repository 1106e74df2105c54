"""The C99 backend: printer (:mod:`.printer`) and emitter (:mod:`.emitter`)."""

from gearsym.symbolic.codegen.c.emitter import CFunctionView, CModuleView, emit_c_files
from gearsym.symbolic.codegen.c.printer import GearsymCPrinter

__all__ = ["CFunctionView", "CModuleView", "GearsymCPrinter", "emit_c_files"]
