"""One router per resource: health, scenes, jobs, stores, render (render + evaluate)."""
