"""Rule modules, one per family: ``general`` (COL0xx), ``structure`` (COL1xx), ``mesh`` (COL2xx),
``skin`` (COL3xx), ``parts`` (COL4xx), ``animation`` (COL5xx), ``proxy`` (COL7xx).  Importing
:func:`validators.registry.all_rules` loads them all."""
