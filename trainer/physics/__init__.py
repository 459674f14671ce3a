"""Oven-experiment simulator: the physics catalogue (shared/specs/physics-catalogue.md) in code.

Public API: ``config.load_config`` / ``config.save_config`` (TOML <-> ``PhysicsConfig``),
``simulate.simulate(cfg, seed) -> Recording``, and ``effects.effect_contribution`` /
``effects.drift`` for evaluating catalogue effects on any temperature history. See
docs/simulator.md.
"""
