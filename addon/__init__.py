"""hemishadow: soft self-shadowing of deforming meshes from environment lighting.

Registration only. The engine (`hemishadow`, shipped as a wheel inside the extension) is
imported lazily by the modules that compute, so registering never loads it.
"""

from . import (cli, farm_panel, handlers, lightmap_panel, lightmap_settings, operators, panels, panorama_live,
               panorama_panel, panorama_settings, probe_panel, properties)

# Properties first: operators and panels refer to them; handlers last, once all is in place.
_modules = (properties, lightmap_settings, panorama_settings, operators, panels, farm_panel, lightmap_panel,
            probe_panel, panorama_panel, cli, handlers, panorama_live)


def register():
    for module in _modules:
        module.register()


def unregister():
    for module in reversed(_modules):
        module.unregister()
