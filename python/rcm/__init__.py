"""Sensorless RCM misalignment estimation for the dVRK PSM (the rcm C++ library).

The package re-exports everything the compiled extension `rcm._core` defines
(docs/howto-python.md), so `rcm.load_recording`, `rcm.InputError`, `rcm.dynamics` and
`rcm.sim` are the extension's own objects. `rcm.batch` (docs/howto-batch.md)
runs studies and other independent work on a Dask cluster; it is imported on
first use, so `import rcm` needs no Dask.
"""

from rcm import _core
from rcm._core import *  # noqa: F401,F403  (every public name of the extension, whatever it defines)

__doc__ = _core.__doc__
__version__ = _core.__version__


def _adopt_names():
    """Names the extension's classes and submodules as the user imports them
    (`rcm.Recording`, `rcm.dynamics.TorqueModel`, not `rcm._core...`), so that
    reprs, tracebacks and help() show the public names."""
    public = {_core.__name__: __name__}
    for attribute in dir(_core):
        value = getattr(_core, attribute)
        if type(value) is type(_core) and value.__name__.startswith(_core.__name__ + "."):
            public[value.__name__] = f"{__name__}.{attribute}"
            value.__name__ = public[value.__name__]
    for module_name in list(public.values()):
        module = _core if module_name == __name__ else globals()[module_name.rsplit(".", 1)[1]]
        for attribute in dir(module):
            value = getattr(module, attribute)
            if isinstance(value, type) and value.__module__ in public:
                try:
                    value.__module__ = public[value.__module__]
                except (AttributeError, TypeError):
                    pass


_adopt_names()
del _adopt_names


def __getattr__(name):
    # rcm.batch without `import rcm.batch` (PEP 562): Dask is imported only then.
    if name == "batch":
        import importlib
        return importlib.import_module("rcm.batch")
    raise AttributeError(f"module 'rcm' has no attribute {name!r}")
