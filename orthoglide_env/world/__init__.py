"""The real lab's world: the non-geometric effects that drives, heat and instruments add
to a virtual machine (:mod:`.table` their sizes and sources, :mod:`.conditions` which are
on, :mod:`.truth` a machine's drawn effects and what they do to its joints and readings,
:mod:`.machine_file` a drawn world kept in a machine file)."""
