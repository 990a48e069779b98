"""The bench's harness: the command (run), what sections share (context, scene, common), mc_ao's side
of each comparison (mcao), the printed table (report) and figures (plot), the memory probe."""
