"""Plain files: TUM trajectories, maps and joints in (``hac import``), arrays out (``hac
export``)."""
