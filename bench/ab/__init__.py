"""Two wpctrl trees compared in one run on one machine."""
