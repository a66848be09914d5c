from tests.fleet_fixtures import mosquitto  # noqa: F401  (the fixture, for this directory)
