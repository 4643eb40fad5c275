"""Device drivers: one sub-package per device family, protocol codecs kept apart from transports."""
