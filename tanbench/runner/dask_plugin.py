"""The Dask worker plugin that gives every worker a sweep's truth maps (needs distributed).

The scheduler keeps a registered plugin and hands it to every worker, those that join
after the sweep started too; ``setup`` installs the maps, ``teardown`` (when the client
unregisters the plugin at the end of the sweep) removes them.
"""

from __future__ import annotations

import pickle

from distributed.diagnostics.plugin import WorkerPlugin


class TruthMapsPlugin(WorkerPlugin):
    """Installs pickled truth maps (terrain key -> Map) on a worker."""

    def __init__(self, maps_pickle: bytes):
        self.maps_pickle = maps_pickle
        self.maps: dict = {}

    def setup(self, worker) -> None:
        from tanbench.runner.executors import install_worker_maps

        self.maps = pickle.loads(self.maps_pickle)
        install_worker_maps(self.maps)

    def teardown(self, worker) -> None:
        from tanbench.terrain import uninstall_truth_maps

        uninstall_truth_maps(self.maps)
