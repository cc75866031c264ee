"""pyfem: 3D explicit seismic analysis of deep caverns in layered rock.

Run a scene from the repository root with Debian's Python::

    /usr/bin/python3 -m pyfem run workflows/scenes/default.toml
    /usr/bin/python3 -m pyfem check workflows/scenes/default.toml

This module stays light on purpose: importing ``pyfem`` loads no dolfinx,
gmsh or compiled kernel; import the submodules that you need.
"""

__version__ = "0.1.0"
