"""The pictures: geometry of the lever, speed-plan, stick and drivetrain diagrams, their
rendering, and the one figure style."""
