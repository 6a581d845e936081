"""The stack assembled from its services' contracts (``services/<name>/contract.py``): the
router's access-control rules (stack/access.py) and the hub that enforces them
(stack/hub.py)."""
