"""eelhost: what runs on the PC beside the tank."""
