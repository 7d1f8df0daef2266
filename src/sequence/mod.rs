//! MOTChallenge sequences with fme's extras (`gt/world.csv`, `depth/`, `meta.json`): reader and writer.
