"""Stage 1, the model: symbolic model definitions (sympy) and parameter files
(:mod:`.definition`). A user's model file imports its names from here."""
from .axle import Axle
from .definition import (DerivedInput, LPVModel, ModelDefinition, ParameterSet, SchedulingBox, SchedulingSignal,
                         check_parameter_values, instantiate, load_parameters, parameter_conditions,
                         parameter_substitution)

__all__ = ["Axle", "DerivedInput", "LPVModel", "ModelDefinition", "ParameterSet", "SchedulingBox", "SchedulingSignal",
           "check_parameter_values", "instantiate", "load_parameters", "parameter_conditions",
           "parameter_substitution"]
