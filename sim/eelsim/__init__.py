"""eelsim: the digital twin of an anguilliform swimming robot."""
