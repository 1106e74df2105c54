"""The Jinja2 templates of every emitted file (package data, found by
gearsym.symbolic.io.package_data and rendered by gearsym.symbolic.codegen.render)."""
