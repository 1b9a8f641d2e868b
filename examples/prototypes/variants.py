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
VARIANTS.update({
    "tight-dvl/9000": {"method": "tight-dvl", "scenario": {"particles": 9000}},
    "tight-dvl/9000-no-floor": {"method": "tight-dvl", "scenario": {"particles": 9000}, "filter": {"min_spread_m": 0.0}},
})

# prototypes (tan_proto.tight): P = posterior-sized regularisation, F0 = no 2 m floor, T = tempering
PT = {"dvl": "tan_proto.tight:TIGHT_DVL", "sbe": "tan_proto.tight:TIGHT_SBE"}
for s in ("dvl", "sbe"):
    VARIANTS.update({
        f"pt-{s}/P": {"method": PT[s], "options": {"regularisation": "posterior"}},
        f"pt-{s}/P-F0": {"method": PT[s], "options": {"regularisation": "posterior", "floor_m": 0.0}},
        f"pt-{s}/T": {"method": PT[s], "options": {"tempering": True}},
        f"pt-{s}/T-P": {"method": PT[s], "options": {"tempering": True, "regularisation": "posterior"}},
        f"pt-{s}/T-P-F0": {"method": PT[s], "options": {"tempering": True, "regularisation": "posterior",
                                                        "floor_m": 0.0}},
    })
for s in ("dvl", "sbe"):
    VARIANTS.update({
        f"pt-{s}/B": {"method": PT[s], "options": {"bias_walk": True}},
        f"pt-{s}/B-F0": {"method": PT[s], "options": {"bias_walk": True, "floor_m": 0.0}},
        f"pt-{s}/B-P-F0": {"method": PT[s], "options": {"bias_walk": True, "regularisation": "posterior",
                                                        "floor_m": 0.0}},
        f"pt-{s}/B-T-P-F0": {"method": PT[s], "options": {"bias_walk": True, "tempering": True,
                                                          "regularisation": "posterior", "floor_m": 0.0}},
        f"pt-{s}/B-T-P": {"method": PT[s], "options": {"bias_walk": True, "tempering": True,
                                                       "regularisation": "posterior"}},
        f"pt-{s}/B-T": {"method": PT[s], "options": {"bias_walk": True, "tempering": True}},
    })
for s in ("dvl", "sbe"):
    VARIANTS.update({
        f"pt-{s}/B-M": {"method": PT[s], "options": {"bias_walk": True, "map_correlation": True}},
        f"pt-{s}/B-M-F0": {"method": PT[s], "options": {"bias_walk": True, "map_correlation": True, "floor_m": 0.0}},
        f"pt-{s}/B-M-T-P-F0": {"method": PT[s], "options": {"bias_walk": True, "map_correlation": True,
                                                            "tempering": True, "regularisation": "posterior",
                                                            "floor_m": 0.0}},
        f"pt-{s}/B-M-T-P": {"method": PT[s], "options": {"bias_walk": True, "map_correlation": True,
                                                         "tempering": True, "regularisation": "posterior"}},
    })

# loose prototypes (tan_proto.loose): G = bias gate (3 sigma) + shape gate (0.9), R = KF-sized re-initialisation,
# T = tempering
PL = "tan_proto.loose:LOOSE_DVL"
VARIANTS.update({
    "pl/G": {"method": PL, "options": {"bias_gate_sigma": 3.0, "shape_gate": 0.9}},
    "pl/R": {"method": PL, "options": {"reloc_kf": True}},
    "pl/G-R": {"method": PL, "options": {"bias_gate_sigma": 3.0, "shape_gate": 0.9, "reloc_kf": True}},
    "pl/G-R-T": {"method": PL, "options": {"bias_gate_sigma": 3.0, "shape_gate": 0.9, "reloc_kf": True,
                                           "tempering": True}},
})
VARIANTS.update({
    "pl/H": {"method": PL, "options": {"heading_offsets": True}},
    "pl/H-G": {"method": PL, "options": {"heading_offsets": True, "bias_gate_sigma": 3.0, "shape_gate": 0.9}},
    "pl/H-G-T": {"method": PL, "options": {"heading_offsets": True, "bias_gate_sigma": 3.0, "shape_gate": 0.9,
                                           "tempering": True}},
})
for s in ("dvl", "sbe"):
    VARIANTS[f"pt-{s}/B-T-F0"] = {"method": PT[s], "options": {"bias_walk": True, "tempering": True, "floor_m": 0.0}}
for s in ("dvl", "sbe"):
    VARIANTS[f"pt-{s}/B-S"] = {"method": PT[s], "options": {"bias_walk": True, "range_sigma": "sensor"}}
    VARIANTS[f"pt-{s}/B-S-F0"] = {"method": PT[s], "options": {"bias_walk": True, "range_sigma": "sensor",
                                                              "floor_m": 0.0}}
    VARIANTS[f"pt-{s}/B-S-T-F0"] = {"method": PT[s], "options": {"bias_walk": True, "range_sigma": "sensor",
                                                                "floor_m": 0.0, "tempering": True}}
    VARIANTS[f"pt-{s}/B-S-T"] = {"method": PT[s], "options": {"bias_walk": True, "range_sigma": "sensor",
                                                             "tempering": True}}
for s in ("dvl", "sbe"):
    VARIANTS[f"pt-{s}/B-L"] = {"method": PT[s], "options": {"bias_walk": True, "relocalise": True}}
    VARIANTS[f"pt-{s}/B-T-L"] = {"method": PT[s], "options": {"bias_walk": True, "relocalise": True,
                                                             "tempering": True}}
for s in ("dvl", "sbe"):
    VARIANTS[f"pt-{s}/B-P"] = {"method": PT[s], "options": {"bias_walk": True, "regularisation": "posterior"}}
VARIANTS.update({
    "pl/H-G-f1": {"method": PL, "options": {"heading_offsets": True, "bias_gate_sigma": 3.0, "shape_gate": 0.9},
                  "filter": {"loose_fix_floor_m": 1.0}},
    "pl/H-f1": {"method": PL, "options": {"heading_offsets": True}, "filter": {"loose_fix_floor_m": 1.0}},
})

# the candidates frozen for the verification runs (docs/filters.md section 4.1), and the same at the particle
# counts whose built-in wall time matches the point-mass filter's (timing.py, area A)
FINAL = {"pt-dvl/B-P-F0": 1400, "pt-sbe/B-P-F0": 2500, "pl/H-G-f1": 2000}
for label, n in FINAL.items():
    VARIANTS[f"{label}@{n}"] = {**VARIANTS[label], "scenario": {"particles": n}}
for s in ("dvl", "sbe"):
    VARIANTS[f"pt-{s}/B-Ph-F0"] = {"method": PT[s], "options": {"bias_walk": True, "regularisation": "posterior",
                                                                "bandwidth": 0.5, "floor_m": 0.0}}
FINAL2 = {"pt-dvl/B-Ph-F0": 1400, "pt-sbe/B-Ph-F0": 2500}
for label, n in FINAL2.items():
    VARIANTS[f"{label}@{n}"] = {**VARIANTS[label], "scenario": {"particles": n}}

# the implemented filters (docs/filters.md section 6): the built-in methods at the recommended defaults after
# issue 24, under their own labels (the built-in labels above are the defaults of whatever code runs them)
for name in ("tight-dvl", "tight-sbe", "loose-dvl"):
    VARIANTS[f"impl/{name}"] = {"method": name}
# label -> particles at which the filter wall time equals the point-mass filter's: timing.py A 3 on runs 0-2, back
# to back (pmf-dvl 1.41 s, pmf-sbe 1.61 s; tight-dvl 3.58 s at 3000, 1.72 at 1500; tight-sbe 2.28 at 3000, 1.88 at
# 2000; loose-dvl 3.84 at 3000, 1.66 at 1500), interpolated linearly and rounded down to 100 (section 6.1)
IMPL_EQUAL_TIME = {"impl/tight-dvl": 1200, "impl/tight-sbe": 1300, "impl/loose-dvl": 1300}
for label, n in IMPL_EQUAL_TIME.items():
    VARIANTS[f"{label}@{n}"] = {**VARIANTS[label], "scenario": {"particles": n}}

# the same rule with the sixth session's code (docs/filters.md section 7.3: timing.py A 3 with each call paying its
# own increments table; pmf-dvl 0.272 s, loose-dvl 0.401 at 3000 and 0.210 at 1500; pmf-dvl 0.234 s, tight-dvl 0.417
# at 3000 and 0.214 at 1500; pmf-sbe 0.421 s, tight-sbe 0.495 at 3000 and 0.317 at 2000); loose-dvl@2000 is the
# uncorrected timing's count, reported and not counted
IMPL_EQUAL_TIME_6 = {"impl/tight-dvl": 1600, "impl/tight-sbe": 2500, "impl/loose-dvl": 1900}
for label, n in [*IMPL_EQUAL_TIME_6.items(), ("impl/loose-dvl", 2000)]:
    VARIANTS[f"{label}@{n}"] = {**VARIANTS[label], "scenario": {"particles": n}}

# the same rule with the twelfth session's code (docs/filters.md section 7.4: timing.py A 3, idle machine; the first
# run counted: pmf-dvl 0.127 s, loose-dvl 0.183 at 3000 and 0.095 at 1500, tight-dvl 0.198 at 3000 and 0.103 at 1500;
# pmf-sbe 0.139 s, tight-sbe 0.159 at 3000 and 0.108 at 2000)
IMPL_EQUAL_TIME_12 = {"impl/tight-dvl": 1800, "impl/tight-sbe": 2600, "impl/loose-dvl": 2000}
for label, n in IMPL_EQUAL_TIME_12.items():
    VARIANTS[f"{label}@{n}"] = {**VARIANTS[label], "scenario": {"particles": n}}

# the same rule with the thirteenth session's code (docs/filters.md section 7.5: timing.py A 3, idle machine; pmf-dvl
# 0.121 s, loose-dvl 0.175 at 3000 and 0.093 at 1500, tight-dvl 0.195 at 3000 and 0.098 at 1500; pmf-sbe 0.143 s,
# tight-sbe 0.171 at 3000 and 0.103 at 2000)
IMPL_EQUAL_TIME_13 = {"impl/tight-dvl": 1800, "impl/tight-sbe": 2500, "impl/loose-dvl": 2000}
for label, n in IMPL_EQUAL_TIME_13.items():
    VARIANTS[f"{label}@{n}"] = {**VARIANTS[label], "scenario": {"particles": n}}
# section 7.6 (loose-dvl with section 15.2's default; timing.py A 3 at 18:46 UTC: pmf-dvl 0.137 s, loose-dvl 0.194 at
# 3000 and 0.096 at 1500)
IMPL_EQUAL_TIME_13_LOOSE = {"impl/loose-dvl": 2100}
for label, n in IMPL_EQUAL_TIME_13_LOOSE.items():
    VARIANTS[f"{label}@{n}"] = {**VARIANTS[label], "scenario": {"particles": n}}

# the likelihood's width (docs/filters.md section 7): S = the sonar's data-sheet noise (filter.range_noise),
# K = bilinear interpolation's own map error (filter.map_representation), on the recommended defaults
ACC = {"C0": {}, "S": {"range_noise": "data-sheet"}, "K": {"map_representation": "bilinear"},
       "SK": {"range_noise": "data-sheet", "map_representation": "bilinear"}}
for cand, flt in ACC.items():
    for name in ("tight-dvl", "tight-sbe", "loose-dvl", "pmf-dvl", "pmf-sbe"):
        VARIANTS[f"acc/{cand}/{name}"] = {"method": name, "filter": dict(flt)}
# round 2 (docs/filters.md section 7.1): existing options only
ACC2 = {"G": {"likelihood": "gaussian"}, "KG": {"map_representation": "bilinear", "likelihood": "gaussian"},
        "W": {"measurement_noise_altitude_m": 1.5}, "C2": {"map_slope_factor": 0.577},
        "Hq": {"regularisation_bandwidth": 0.25}}
for cand, flt in ACC2.items():
    for name in ("tight-dvl", "tight-sbe", "loose-dvl", "pmf-dvl", "pmf-sbe"):
        VARIANTS[f"acc/{cand}/{name}"] = {"method": name, "filter": dict(flt)}
