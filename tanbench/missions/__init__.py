"""Recorded missions: tanbench's open mission-log format, and replaying methods over a log.

A mission log is a directory of tables (Parquet or CSV, units in the column names) and a
small metadata file; docs/missions.md is its specification. The modules follow the data:

* :mod:`tanbench.missions.spec`: the format itself: the metadata model, the tables and
  their columns, the accepted units;
* :mod:`tanbench.missions.logfile`: reading and writing a log directory (:class:`MissionLog`);
* :mod:`tanbench.missions.simulated`: a simulated run as a log (``tanbench simulate --log``);
* :mod:`tanbench.missions.observe`: a log and a map as the :class:`~tanbench.simulation.Observations`
  a method is given and the reference that scoring reads;
* :mod:`tanbench.missions.replay`: every method over a log and a map, scored when the log has a
  reference track (``tanbench replay``).
"""
