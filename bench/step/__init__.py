"""The control step: wpctrl against its torch baseline, per mode and option."""
