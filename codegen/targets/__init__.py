"""Export targets beyond the Python extension: the FMU (:mod:`.fmu`, FMI 2.0 headers in
``fmi2/``), the float32 build (:mod:`.float32`), the Cortex-M cross-build (:mod:`.cortexm`) and
the MISRA C check (:mod:`.misra`)."""
