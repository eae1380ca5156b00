# Component: system (targets are added by the component's owner)
