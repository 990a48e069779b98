"""What mc_ao is measured against: Cycles' AO bake (cycles) and raw Embree on the bake's own rays (embree)."""
