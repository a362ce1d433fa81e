"""One run's life: building its components, collecting episodes, the trainer, checkpoints, the run
directory, metrics and progress, and loading and evaluating a finished run."""
