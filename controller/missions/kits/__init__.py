"""The kits of a mission: everything one flight needs, built for each way to fly (see `base.FlightKit`)."""
