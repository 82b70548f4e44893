"""The reference stack: the float64 oracle, the one error model, the Mitsuba 3 bridge, the
validation of images and rays, `check` and `stability`. The product (model, engine, io) never
imports it; only the commands that compare do."""
