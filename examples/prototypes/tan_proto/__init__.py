"""Prototype particle filters for issue 24, written as user plug-ins (docs/methods.md).

``tight``: the tightly coupled 8-state PF driven update by update from Python over
tanbench's jitted kernels; with every option off it is the built-in ``tight-dvl`` /
``tight-sbe`` bit for bit (``check_identity.py``). Its options switch on the mechanisms
measured in docs/filters.md: no 2 m floor, regularisation sized to the posterior
covariance, progressive correction (likelihood tempering), divergence detection from the
filter's own quantities with a global re-localisation.

``loose``: the closed-loop loose TAN with fix gating on the PF cloud's own shape.
"""
