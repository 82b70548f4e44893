"""Programs and launches: each kernel's variant, source and signature, built and run."""
