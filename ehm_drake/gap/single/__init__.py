"""One subject's gap diagnosis: the ordinary pass and the structural pass."""
