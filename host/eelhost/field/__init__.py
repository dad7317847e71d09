"""At the tank: the run loop of ``eelbot run`` and the recorder of what happened."""
