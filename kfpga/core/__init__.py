"""The core layer: the fixed-point format, the operations and their backends, the filter spec and
registry, the configuration, default formats, parameter checks and the errors users can cause.

It imports nothing of the layers above it (``model``, ``hw``, ``sim``, ``flows``, ``verify``,
``cli``); the registry imports a filter's modules by name, when they are asked for.
"""
