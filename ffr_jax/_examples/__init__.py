"""Published benchmark problems used to check the optimisers (not multibody cases)."""
