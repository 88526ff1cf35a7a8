"""Configuration: the YAML schema (:mod:`.schema`) and the sections the bridge, the SIL vehicle
and the target estimator add (:mod:`.bridge`, :mod:`.sil`, :mod:`.target`).

Importing the package registers every section, so any configuration accepts (and strictly
checks) them whoever loads it.
"""

from mpf_mavlink.config import bridge, sil, target  # noqa: F401  (registers the sections)
from mpf_mavlink.config.schema import Config, apply_override, config_from_dict, load_config

__all__ = ["Config", "apply_override", "config_from_dict", "load_config"]
