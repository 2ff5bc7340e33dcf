"""``colossus bench`` (the top floor, beside the command line): every benchmark prints ratios
against baselines run in the same process.  One module per benchmark (:mod:`.import_`,
:mod:`.validate`, :mod:`.runtime`) and the synthetic skinned characters they use (:mod:`.synth`).
Synthetic rows are best cases; say so wherever they are printed."""
