"""Configuration: the YAML schema (:mod:`.schema`) with the sections of the bridge, the SIL
vehicle and the target estimator (:mod:`.bridge`, :mod:`.sil`, :mod:`.target`), every one a
typed, strictly validated dataclass; :mod:`.scenario` builds the guidance core's objects from
them and :mod:`.reference` writes the reference of every key (docs/configuration.md).
"""

from mpf_mavlink.config.schema import Config, apply_override, config_from_dict, load_config

__all__ = ["Config", "apply_override", "config_from_dict", "load_config"]
