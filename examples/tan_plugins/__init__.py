"""Example tanbench plug-in methods (docs/methods.md): a dead-reckoning baseline and a small
numpy particle filter. Put this folder's parent on PYTHONPATH and name the methods in a
sweep as ``tan_plugins.dead_reckoning:run`` and ``tan_plugins.numpy_pf:METHOD``."""
