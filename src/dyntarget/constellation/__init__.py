"""Many satellites on real orbits, one shared picture of the world's active volcanoes.

``dyntarget constellation`` (``docs/constellation.md``): SGP4 orbits over a rotating WGS 84
Earth (:mod:`~dyntarget.constellation.orbits`), the GVP volcano catalog, a stochastic
eruption model with the synthetic plume model's plumes and cloud cover
(:mod:`~dyntarget.constellation.world`), overflight windows from the pass scheduler's
kinematics (:mod:`~dyntarget.constellation.geometry`), cueing through a shared board and
geostationary imagers (:mod:`~dyntarget.constellation.simulate`), allocation greedy,
distributed or exact (:mod:`~dyntarget.constellation.allocate`), outputs and sweeps on Dask
(:mod:`~dyntarget.constellation.run`) and the figures (:mod:`~dyntarget.constellation.draw`).
"""
