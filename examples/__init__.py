"""The example XML test lists (``warpcloth.examples`` once installed): ``warpcloth list --examples``
prints their paths, ``warpcloth sweep --example quick`` runs one."""
