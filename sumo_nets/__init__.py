"""muvsim: sumo_nets package -- SUMO networks, demand and scenario files.

* :mod:`sumo_nets.sumo_tools` -- locating and running SUMO's command-line tools;
* :mod:`sumo_nets.generate` -- deterministic, cached grids, random demand,
  routing of trips/flows and ``.sumocfg`` files;
* :mod:`sumo_nets.scenario` -- validated scenario TOML files (built-ins in
  ``scenarios/``), :func:`~sumo_nets.scenario.materialise`,
  :func:`~sumo_nets.scenario.read_sumocfg`.

Nothing here imports libsumo, traci or sumolib (that is ``bridge/``'s job).
"""
