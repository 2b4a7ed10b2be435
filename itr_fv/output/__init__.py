"""Output for a reader: VTK image files, off-screen renders of fields and particles."""
