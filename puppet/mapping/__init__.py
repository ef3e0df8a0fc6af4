"""Mapping: control events -> filter chains -> channel values, from a TOML mapping file."""

from puppet.mapping.config import BindingSpec, MappingSpec, load_mapping, parse_mapping
from puppet.mapping.engine import Mapper, device_matches
from puppet.mapping.targets import ChannelInfo, Target, Vocabulary

__all__ = ["BindingSpec", "ChannelInfo", "Mapper", "MappingSpec", "Target", "Vocabulary",
           "device_matches", "load_mapping", "parse_mapping"]
