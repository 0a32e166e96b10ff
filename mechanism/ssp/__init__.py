"""The system as SSP 1.0 (System Structure and Parameterization): data, files, reading, running.

- ``system``: the two components, connectors, connections and named parameter sets, as data;
- ``generate``: the SSD and .ssv files from the dataclass defaults, and the .ssp archive (``pack``);
- ``reader``: an archive into checked dataclasses (``load_ssp``);
- ``tools``: the archive run in other FMI tools (fmpy.ssp, libcosim, ecos);
- ``cli``: ``ssp-generate``, ``ssp-pack``, ``ssp-simulate`` and ``run --ssp`` (our master on an SSP);
- ``slaves/``: the SliderCrank FMU's slave (the mechanism as an FMU, for the two-FMU system).
"""
from mechanism.ssp.generate import expected_files, generate, pack
from mechanism.ssp.reader import (Component, Connection, Connector, FmuVariable, SspSystem,
                                  check_component_parameters, load_ssp, validate_schema)
from mechanism.ssp.system import (ARCHIVE_NAME, BEARING, BEARING_INPUTS, COMPONENTS, CONNECTIONS,
                                  COUPLING_OUTPUTS, DEFAULT_PARAMETER_SET, DEFAULT_STEP, DEFAULT_STOP,
                                  MECHANISM, PARAMETER_SETS, SOURCE_DIR, SOURCE_SSD, SSD_IN_ARCHIVE,
                                  SSD_SUFFIX, SYSTEM_NAME, ParameterSetSpec, SspError, parameter_units,
                                  ssv_path, unit_definitions, variant_ssd_name)

__all__ = ["ARCHIVE_NAME", "BEARING", "BEARING_INPUTS", "COMPONENTS", "CONNECTIONS", "COUPLING_OUTPUTS",
           "Component", "Connection", "Connector", "DEFAULT_PARAMETER_SET", "DEFAULT_STEP", "DEFAULT_STOP",
           "FmuVariable", "MECHANISM", "PARAMETER_SETS", "ParameterSetSpec", "SOURCE_DIR", "SOURCE_SSD",
           "SSD_IN_ARCHIVE", "SSD_SUFFIX", "SYSTEM_NAME", "SspError", "SspSystem", "check_component_parameters",
           "expected_files", "generate", "load_ssp", "pack", "parameter_units", "ssv_path",
           "unit_definitions", "validate_schema", "variant_ssd_name"]
