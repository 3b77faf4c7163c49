"""What API processes and workers share beyond the store: the active model, bootstrap, metrics."""
