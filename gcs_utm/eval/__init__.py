"""Fast-time closed-loop evaluation of the resolutions: scenario runs with an automatic
operator (:mod:`.run`), what each run says (:mod:`.summary`), and a seeded encounter
generator (:mod:`.generator`). ``gcs-utm eval`` and ``gcs-utm bench resolution`` drive it."""
