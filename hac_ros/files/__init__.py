"""Plain files: TUM trajectories, maps and joints in (``hac import``), arrays out (``hac
export``), and the parameters file of the node and every command (:mod:`.params_file`)."""
