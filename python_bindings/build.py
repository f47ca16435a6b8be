"""``python -m python_bindings.build [NAME ...]``: compile generated observers into extensions
(the same as ``uiogen build``; the build itself is :mod:`codegen.extension.build`)."""
import sys

from codegen.extension.build import (GLUE_FLAGS, STRICT_FLAGS, build_extension, generated_names, main,
                                     observer_sources)

__all__ = ["GLUE_FLAGS", "STRICT_FLAGS", "build_extension", "generated_names", "main",
           "observer_sources"]

if __name__ == "__main__":
    sys.exit(main())
