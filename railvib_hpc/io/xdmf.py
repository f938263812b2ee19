"""XDMF 3 helpers shared by the writers of modes, fields and stresses."""

from __future__ import annotations


def temporal_xdmf(name: str, grids: list[str]) -> str:
    """Wrap uniform grids in an XDMF 3 temporal collection."""
    body = "\n".join(grids)
    return f"""<?xml version="1.0" ?>
<Xdmf Version="3.0">
  <Domain>
    <Grid Name="{name}" GridType="Collection" CollectionType="Temporal">
{body}
    </Grid>
  </Domain>
</Xdmf>
"""
