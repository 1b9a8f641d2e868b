"""The method variants ``measure.py`` runs: a name -> the method, its options, filter settings.

Built-ins at the recommended defaults, built-in ablations through existing ``filter.*``
options, and the prototypes of ``tan_proto`` (plug-ins written against the public method
API, reusing tanbench's jitted kernels).
"""

BUILTIN = ("tight-dvl", "tight-sbe", "loose-dvl", "pmf-dvl", "pmf-sbe", "mpf-dvl")

VARIANTS = {name: {"method": name} for name in BUILTIN}
# built-in ablations (existing options)
VARIANTS.update({
    "tight-dvl/no-floor": {"method": "tight-dvl", "filter": {"min_spread_m": 0.0}},
    "tight-sbe/no-floor": {"method": "tight-sbe", "filter": {"min_spread_m": 0.0}},
    "loose-dvl/no-floor": {"method": "loose-dvl", "filter": {"min_spread_m": 0.0}},
})
