"""The stack assembled from its services' contracts (``services/<name>/contract.py``): the
router's access-control rules (stack/access.py, from who may do what: stack/access_table.py;
who runs at all: stack/principals.py) and the hub that enforces them (stack/hub.py)."""
